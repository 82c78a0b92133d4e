"""Fixtures: a tiny object pool built with the objview binary and a real `objview serve`.

The binary is ``$OBJVIEW_BIN``, else the most recently built of
``$CARGO_TARGET_DIR/{release,ci}/objview`` and ``<repo>/target/{release,ci}/objview``, else
``objview`` on PATH.  Without one the server tests fail with a message saying so (set
``OBJVIEW_SKIP_SERVER_TESTS=1`` to skip them instead).

The pool (built in well under a second): the built-in ``cube`` and ``cone`` normalized by
``objview pool build`` (mesh + sampled ground-truth cloud), and three split files over it:
``tiny`` (hidden: cube, cone), ``tiny-public`` (cube, served with ``--public``) and ``solo``
(cube only, for the replay test).  The server runs with two bearer tokens, ``--normalize none``
(the pool is normalized, as `objview run` on it) and a database and reference cache in a
temporary folder.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional

import pytest

import objview

REPO = Path(__file__).resolve().parents[2]
TOKEN = "t0ken-main"
OTHER_TOKEN = "t0ken-other"
START = float(3 ** 0.5)


def find_binary() -> Optional[str]:
    """``$OBJVIEW_BIN``, else the newest of the cargo build outputs, else ``objview`` on PATH."""
    env = os.environ.get("OBJVIEW_BIN")
    if env:
        return env
    cands: List[Path] = []
    ctd = os.environ.get("CARGO_TARGET_DIR")
    if ctd:
        cands += [Path(ctd) / "release" / "objview", Path(ctd) / "ci" / "objview"]
    cands += [REPO / "target" / "release" / "objview", REPO / "target" / "ci" / "objview"]
    found = [c for c in cands if c.is_file() and os.access(c, os.X_OK)]
    if found:  # the newest build: an older profile's binary may predate `serve`
        return str(max(found, key=lambda c: c.stat().st_mtime))
    return shutil.which("objview")


def run_bin(binary: str, *args: str, cwd: Optional[Path] = None, timeout: float = 300) -> str:
    p = subprocess.run(
        [binary, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout
    )
    if p.returncode != 0:
        raise RuntimeError(f"objview {' '.join(args)} failed ({p.returncode}):\n{p.stderr}")
    return p.stdout


@pytest.fixture(scope="session")
def objview_bin() -> str:
    b = find_binary()
    if b is None:
        msg = (
            "no objview binary: set OBJVIEW_BIN, or build it (cargo build --release) — "
            "the server tests need `objview serve`"
        )
        if os.environ.get("OBJVIEW_SKIP_SERVER_TESTS") == "1":
            pytest.skip(msg)
        pytest.fail(msg)
    help_text = subprocess.run([b, "serve", "--help"], capture_output=True, text=True).stdout
    if "--pool" not in help_text:
        pytest.fail(f"{b} has no `serve` command with --pool (is it an old build?)")
    return b


class Pool:
    def __init__(self, root: Path):
        self.root = root
        self.entries: Dict[str, dict] = {}

    def split_file(self, name: str) -> Path:
        return self.root / f"{name}.json"


@pytest.fixture(scope="session")
def pool(objview_bin, tmp_path_factory) -> Pool:
    root = tmp_path_factory.mktemp("pool")
    run_bin(objview_bin, "objects", "synth", "--out", str(root / "raw"))
    run_bin(
        objview_bin,
        "pool", "build", str(root / "raw" / "cube.obj"), str(root / "raw" / "cone.obj"),
        "--out", str(root / "pool"), "--threads", "2",
    )
    built = json.loads((root / "pool" / "pool.json").read_text())
    entries = {}
    for e in built:  # paths relative to pool/, made relative to root/ where the splits live
        entries[e["uid"]] = {
            "uid": e["uid"],
            "mesh": f"pool/{e['mesh']}",
            "gt_cloud": f"pool/{e['gt_cloud']}",
        }
    p = Pool(root)
    p.entries = entries
    for name, uids in {"tiny": ["cube", "cone"], "tiny-public": ["cube"], "solo": ["cube"]}.items():
        p.split_file(name).write_text(json.dumps([entries[u] for u in uids], indent=1))
    return p


class Server:
    def __init__(self, url: str, proc: subprocess.Popen, log: Path, root: Path):
        self.url = url
        self.proc = proc
        self.log = log
        self.root = root

    def client(self, token: Optional[str] = TOKEN, **kw) -> objview.Client:
        return objview.Client(self.url, token=token, **kw)

    def log_text(self) -> str:
        try:
            return self.log.read_text(errors="replace")
        except OSError:
            return ""


@contextlib.contextmanager
def start_server(objview_bin: str, pool: Pool, root: Path, *extra: str):
    """Run `objview serve` over the pool's splits on a free loopback port until the block ends."""
    tokens = root / "tokens.txt"
    tokens.write_text(f"# test tokens\n{TOKEN} main\n{OTHER_TOKEN} other\n")
    log = root / "serve.log"
    args = [
        objview_bin, "serve",
        "--pool", str(pool.split_file("tiny")), str(pool.split_file("tiny-public")),
        str(pool.split_file("solo")),
        "--public", "tiny-public",
        "--addr", "127.0.0.1:0",  # the server picks a free port and prints it
        "--db", str(root / "db.sqlite"),
        "--tokens", str(tokens),
        "--cache-dir", str(root.parent / "reference-cache"),
        "--normalize", "none",
        *extra,
    ]
    logf = open(log, "wb")
    proc = subprocess.Popen(args, stdout=logf, stderr=subprocess.STDOUT, cwd=root)
    try:
        url = None
        deadline = time.time() + 60
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"objview serve exited with {proc.returncode}:\n{log.read_text()}")
            if time.time() > deadline:
                raise RuntimeError(f"objview serve not healthy within 60 s:\n{log.read_text()}")
            m = re.search(r"listening on (http://[0-9.]+:\d+)", log.read_text(errors="replace"))
            if m:
                url = m.group(1)
                try:
                    if objview.Client(url, timeout=2).health().get("status") == "ok":
                        break
                except objview.ObjViewError:
                    pass
            time.sleep(0.1)
        yield Server(url, proc, log, root)
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        logf.close()


@pytest.fixture(scope="session")
def server(objview_bin, pool, tmp_path_factory):
    with start_server(objview_bin, pool, tmp_path_factory.mktemp("server")) as srv:
        yield srv


@pytest.fixture
def client(server) -> objview.Client:
    return server.client()


@pytest.fixture(scope="session")
def issue17_server(server):
    """Skips when the binary predates the server side of issue 17 (branch issue17-rs: the
    ``GET /v1/episodes`` listing, gzip answers): such a build answers that route 405.  Any
    build that has the route must pass the tests that use this fixture (listing, orphans,
    gzip)."""
    try:
        server.client().request("GET", "/v1/episodes")
    except objview.MethodNotAllowed:
        pytest.skip("this objview binary has no GET /v1/episodes (it predates issue17-rs): "
                    "listing episodes, abort_orphans and gzip answers cannot be checked")
    return server


def pytest_report_header(config):
    return f"objview binary: {find_binary()}; python {sys.version.split()[0]}"
