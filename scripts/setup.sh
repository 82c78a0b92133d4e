#!/usr/bin/env bash
# One-time set-up shared by the README's two commands: checks the Rust toolchain and installs
# the system packages that a build or test step loads, each found by a probe that looks for it
# the way that step does (scripts/lib/probes.sh, tested by scripts/test-probes.sh):
#   cc, c++        the cc crate (SQLite, bundled) and HiGHS's C++ sources      gcc, g++
#   cmake          HiGHS is built from source by the `highs-sys` build script  cmake
#   libclang       bindgen (highs-sys) dlopens the libclang C library          libclang-dev
#   python3 venv   python/run_tests.sh makes a virtual environment with pip    python3, python3-venv
# Safe to run repeatedly; prints what it installs. OBJVIEW_SETUP_DRY_RUN=1 prints the missing
# packages and installs nothing.
set -euo pipefail
. "$(dirname "$0")/lib/probes.sh"

need_pkgs=()
command -v cc >/dev/null 2>&1 || need_pkgs+=(gcc)
command -v c++ >/dev/null 2>&1 || need_pkgs+=(g++)
command -v cmake >/dev/null 2>&1 || need_pkgs+=(cmake)
# libclang-dev also brings clang's builtin headers (stddef.h…), which bindgen needs to parse.
if ! probe_find_libclang >/dev/null; then
  need_pkgs+=(libclang-dev)
fi
if ! command -v python3 >/dev/null 2>&1; then
  need_pkgs+=(python3 python3-venv)
elif ! probe_python_venv; then
  need_pkgs+=(python3-venv)
fi

if [ ${#need_pkgs[@]} -gt 0 ]; then
  if [ -n "${OBJVIEW_SETUP_DRY_RUN:-}" ]; then
    echo "setup: missing ${need_pkgs[*]}"
    exit 0
  fi
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "setup: installing ${need_pkgs[*]}" >&2
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_pkgs[@]}" >/dev/null
  else
    echo "setup: please install: ${need_pkgs[*]}" >&2
    exit 1
  fi
  # What was installed must now be found by the same probes, or the build would fail later
  # with a less clear message.
  if ! probe_find_libclang >/dev/null; then
    echo "setup: libclang-dev is installed but bindgen's libclang library is still not found" >&2
    exit 1
  fi
elif [ -n "${OBJVIEW_SETUP_DRY_RUN:-}" ]; then
  echo "setup: nothing missing"
  exit 0
fi

if ! command -v cargo >/dev/null 2>&1; then
  [ -f "$HOME/.cargo/env" ] && . "$HOME/.cargo/env"
fi
command -v cargo >/dev/null 2>&1 || { echo "setup: cargo not found (install Rust via rustup)" >&2; exit 1; }
