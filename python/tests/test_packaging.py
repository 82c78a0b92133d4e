"""The package installs from a read-only copy of python/ (the build writes nothing into the
source tree) and ships py.typed."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import venv
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def make_read_only(root: Path) -> None:
    for p in [root, *root.rglob("*")]:
        mode = p.stat().st_mode
        p.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))


def test_install_from_a_read_only_checkout(tmp_path):
    src = tmp_path / "ro" / "python"
    shutil.copytree(HERE, src, ignore=shutil.ignore_patterns(
        ".venv", "build", "*.egg-info", "__pycache__", ".pytest_cache", ".mypy_cache",
        ".ruff_cache", "tests", "examples"))
    make_read_only(src.parent)
    target = tmp_path / "venv"
    venv.create(target, with_pip=False)
    env = {**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    wheels = tmp_path / "wheels"
    try:
        # What `pip install ./python` does, in two steps: build the wheel from the read-only
        # source (--no-build-isolation: the hatchling of the test extra, no network needed;
        # setuptools failed here, writing objview.egg-info into the source), then install it
        # into a fresh venv (--no-deps: numpy and gymnasium are not needed to check the files).
        p = subprocess.run(
            [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
             "--no-cache-dir", "-w", str(wheels), str(src)],
            capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path,
        )
        assert p.returncode == 0, p.stdout + p.stderr
        (whl,) = wheels.glob("objview-*.whl")
        p = subprocess.run(
            [sys.executable, "-m", "pip", "--python", str(target / "bin" / "python"), "install",
             "--no-deps", "--no-cache-dir", str(whl)],
            capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path,
        )
        assert p.returncode == 0, p.stdout + p.stderr
    finally:
        for q in [src.parent, *src.parent.rglob("*")]:
            q.chmod(q.stat().st_mode | stat.S_IWUSR)
    site = list(target.glob("lib/python*/site-packages"))[0]
    pkg = site / "objview"
    assert (pkg / "__init__.py").is_file() and (pkg / "py.typed").is_file()
    assert (pkg / "camera.py").is_file() and (pkg / "types.py").is_file()
    assert not list(src.glob("*.egg-info")) and not (src / "build").exists()
    # The installed copy imports (numpy and gymnasium from this environment).
    code = "import objview, sys; print(objview.__file__)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(site)}, cwd=tmp_path,
                         timeout=120, check=True).stdout
    assert out.strip().startswith(str(pkg))
