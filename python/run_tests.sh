#!/usr/bin/env bash
# The Python package's tests: a virtual environment under python/.venv (reused when present),
# `pip install ./python[test]`, `ruff check`, `mypy --strict` on the package, then pytest against
# a real `objview serve`.
#
# The objview binary: $OBJVIEW_BIN, else the newest of $CARGO_TARGET_DIR/{release,ci}/objview,
# target/{release,ci}/objview of the repository, `objview` on PATH (see tests/conftest.py).
# Extra arguments go to pytest (e.g. `bash python/run_tests.sh -k gym -x`).
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
cd "$HERE"
PYTHON="${PYTHON:-python3}"
VENV="${OBJVIEW_VENV:-$HERE/.venv}"
if [ ! -x "$VENV/bin/python" ]; then
    echo "== creating $VENV"
    "$PYTHON" -m venv "$VENV"
fi
echo "== pip install ./python[test]"
"$VENV/bin/python" -m pip install --quiet --upgrade pip >/dev/null 2>&1 || true
# Non-editable, so the tests run against the installed package, as a user gets it.
"$VENV/bin/python" -m pip install --quiet --upgrade "$HERE[test]"
echo "== ruff check"
"$VENV/bin/python" -m ruff check --no-cache "$HERE"
echo "== mypy --strict objview"
"$VENV/bin/python" -m mypy --strict --cache-dir /dev/null "$HERE/objview"
echo "== pytest"
# Run from tests/ so that `import objview` resolves to the installed package, not ./objview.
cd "$HERE/tests"
exec "$VENV/bin/python" -m pytest -q -p no:cacheprovider "$@" .
