"""The quickstarts work as written: the code blocks of python/README.md and of the top-level
README's server and Python sections run against a temporary server.

A block is marked by an HTML comment on the line before its fence (blank lines allowed):

- ``<!-- docs-test: run -->``: run it — ``sh`` with bash (``set -euo pipefail``), ``python``
  with this interpreter — in a temporary working folder;
- ``<!-- docs-test: server -->``: the ``objview serve`` command, started in the background
  (then the next blocks run against it, and it is stopped at the end);
- ``<!-- docs-test: skip (reason) -->``: not run, for the stated reason.

Every code block of the checked sections must carry one of them (so a new block is not silently
left out).  The one change made to the text: the address ``127.0.0.1:8080`` becomes a free
port (``--addr 127.0.0.1:0`` for the server, its printed URL for the clients), because other
processes may hold port 8080.  The working folder holds what the commands expect: ``objview``
and ``python`` on PATH (the tested binary, this interpreter), the split files
``out/demo/splits/main_hidden_test.json`` / ``main_train_public.json`` (the test pool's cube and
cone, not the demo's objects: building the demo takes far too long) and ``python/`` (this
package's folder, for the examples).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REPO

MARK = re.compile(r"<!--\s*docs-test:\s*(run|server|skip)\b\s*(.*?)\s*-->")
FENCE = re.compile(r"^```(\w*)\s*$")


def blocks(text: str):
    """(kind, reason, lang, code, line) of every fenced block, kind None when unmarked."""
    out = []
    lines = text.splitlines()
    i = 0
    pending = None
    while i < len(lines):
        m = MARK.search(lines[i])
        if m:
            pending = (m.group(1), m.group(2), i + 1)
            i += 1
            continue
        f = FENCE.match(lines[i])
        if f:
            j = i + 1
            while not lines[j].startswith("```"):
                j += 1
            kind, reason = (pending[0], pending[1]) if pending else (None, "")
            out.append((kind, reason, f.group(1), "\n".join(lines[i + 1 : j]) + "\n", i + 1))
            pending = None
            i = j + 1
            continue
        if lines[i].strip():
            pending = None if not lines[i].startswith("<!--") else pending
        i += 1
    return out


def section(text: str, start: str, end: str) -> str:
    a = text.index(start)
    return text[a : text.index(end, a + len(start))]


def python_readme():
    return (REPO / "python" / "README.md").read_text()


def top_readme_sections():
    text = (REPO / "README.md").read_text()
    return (section(text, "## Evaluation server (`objview serve`)", "\n## Python client")
            + section(text, "## Python client and Gymnasium environment", "\n## Errors and bad input"))


DOCS = {"python/README.md": python_readme, "README.md": top_readme_sections}


@pytest.mark.parametrize("doc", sorted(DOCS))
def test_every_block_is_marked(doc):
    bl = blocks(DOCS[doc]())
    assert bl, doc
    unmarked = [(line, lang) for kind, _, lang, _, line in bl if kind is None]
    assert not unmarked, f"{doc}: code blocks without a docs-test marker at lines {unmarked}"
    for kind, reason, _, _, line in bl:
        if kind == "skip":
            assert reason.strip("() "), f"{doc}:{line}: a skipped block needs a stated reason"
    kinds = [k for k, *_ in bl]
    assert kinds.count("server") == 1 and "run" in kinds


@pytest.fixture
def workdir(tmp_path, pool, objview_bin):
    work = tmp_path / "work"
    splits = work / "out" / "demo" / "splits"
    splits.mkdir(parents=True)
    for name, uids in {"main_hidden_test": ["cube", "cone"], "main_train_public": ["cube"]}.items():
        entries = [{k: (str(pool.root / v) if k != "uid" else v) for k, v in pool.entries[u].items()}
                   for u in uids]
        (splits / f"{name}.json").write_text(json.dumps(entries))
    (work / "python").symlink_to(REPO / "python")
    bindir = tmp_path / "bin"
    bindir.mkdir()
    (bindir / "objview").symlink_to(Path(objview_bin).resolve())
    env = {k: v for k, v in os.environ.items() if not k.startswith("OBJVIEW_")}
    env.update({
        # `python` is this interpreter: its folder (a venv's bin/) first on PATH.
        "PATH": os.pathsep.join([str(bindir), str(Path(sys.executable).parent),
                                 env.get("PATH", "")]),
        "XDG_CACHE_HOME": str(tmp_path / "cache"),  # the server's reference cache
        "PYTHONUNBUFFERED": "1",
    })
    return work, env


def start(code: str, work: Path, env):
    code = code.replace("127.0.0.1:8080", "127.0.0.1:0")
    assert "objview serve" in code
    log = work / "docs-serve.log"
    logf = open(log, "wb")
    proc = subprocess.Popen(["bash", "-c", "exec " + code.strip()], cwd=work, env=env,
                            stdout=logf, stderr=subprocess.STDOUT)
    deadline = time.time() + 60
    while True:
        text = log.read_text(errors="replace")
        m = re.search(r"listening on (http://[0-9.]+:\d+)", text)
        if m:
            return proc, logf, m.group(1)
        if proc.poll() is not None or time.time() > deadline:
            proc.kill()
            raise AssertionError(f"the README's server command failed:\n{code}\n{text}")
        time.sleep(0.1)


@pytest.mark.parametrize("doc", sorted(DOCS))
def test_quickstart_blocks_run(doc, workdir):
    work, env = workdir
    proc = logf = None
    url = None
    ran = 0
    try:
        for kind, _, lang, code, line in blocks(DOCS[doc]()):
            if kind == "server":
                proc, logf, url = start(code, work, env)
                continue
            if kind != "run":
                continue
            if url is not None:
                code = code.replace("http://127.0.0.1:8080", url)
            if lang == "python":
                cmd = [sys.executable, "-c", code]
            elif lang in ("sh", "bash"):
                cmd = ["bash", "-c", "set -euo pipefail\n" + code]
            else:
                raise AssertionError(f"{doc}:{line}: cannot run a {lang!r} block")
            p = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True,
                               timeout=300)
            assert p.returncode == 0, (
                f"{doc}:{line}: the block failed ({p.returncode}):\n{code}\n"
                f"--- stdout\n{p.stdout}\n--- stderr\n{p.stderr}")
            ran += 1
    finally:
        if proc is not None:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            logf.close()
    assert url is not None and ran >= 2
