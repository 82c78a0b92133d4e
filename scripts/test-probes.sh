#!/usr/bin/env bash
# Tests of the set-up probes (scripts/lib/probes.sh) against fake directory trees: a probe that
# decides whether to install a package must itself be able to fail. Run by scripts/test.sh.
set -uo pipefail
. "$(dirname "$0")/lib/probes.sh"

pass=0
fail=0
check() { # check NAME EXPECTED(0|1) COMMAND...
  local name="$1" want="$2"
  shift 2
  "$@" >/dev/null 2>&1
  local got=$?
  [ "$got" -ne 0 ] && got=1
  if [ "$got" = "$want" ]; then
    pass=$((pass + 1))
  else
    fail=$((fail + 1))
    echo "FAIL: $name (wanted $([ "$want" = 0 ] && echo present || echo missing))" >&2
  fi
}

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
# Each case gets its own tree under PROBE_ROOT; the machine's own llvm-config, LD_LIBRARY_PATH
# and LIBCLANG_PATH are kept out of it.
fake_tree() { # fake_tree NAME FILE... → prints the root
  local root="$tmp/$1"
  shift
  mkdir -p "$root/usr/lib" "$root/usr/local/lib"
  local f
  for f in "$@"; do
    mkdir -p "$root/$(dirname "$f")"
    : >"$root/$f"
  done
  echo "$root"
}
probe_in() { # probe_in ROOT [VAR=VALUE...]
  local root="$1"
  shift
  env -u LIBCLANG_PATH LD_LIBRARY_PATH= LLVM_CONFIG_PATH=/nonexistent/llvm-config PROBE_ROOT="$root" "$@" \
    bash -c '. "$0"; probe_find_libclang' "$(dirname "$0")/lib/probes.sh"
}

# File names: the C library in every spelling clang-sys accepts, never the C++ one.
for n in libclang.so libclang.so.1 libclang.so.14.0.6 libclang-14.so libclang-14.so.1 libclang-14.0.6.so.1; do
  check "name $n" 0 probe_is_libclang_name "$n"
done
for n in libclang-cpp.so libclang-cpp.so.14 libclang_rt.asan-x86_64.so libclangBasic.so libclang.a \
  libclang.so.txt libclang-cpp14.so.1; do
  check "name $n" 1 probe_is_libclang_name "$n"
done

# The fresh Debian image: only libclang-cpp (libclang-cpp14) → missing.
root="$(fake_tree cpp-only usr/lib/llvm-14/lib/libclang-cpp.so.14 usr/lib/x86_64-linux-gnu/libclang-cpp.so.14)"
check "only libclang-cpp.so.14" 1 probe_in "$root"
# …also when llvm-config points at that directory.
cat >"$tmp/llvm-config-cpp" <<CFG
#!/bin/sh
echo "$root/usr/lib/llvm-14/lib"
CFG
chmod +x "$tmp/llvm-config-cpp"
check "llvm-config dir with only libclang-cpp" 1 probe_in "$root" LLVM_CONFIG_PATH="$tmp/llvm-config-cpp"
# libclang1-14 / libclang-dev layouts → present.
root="$(fake_tree so1 usr/lib/llvm-14/lib/libclang-cpp.so.14 usr/lib/llvm-14/lib/libclang.so.1)"
check "libclang.so.1 under llvm-14" 0 probe_in "$root"
root="$(fake_tree multiarch usr/lib/x86_64-linux-gnu/libclang-14.so.1)"
check "libclang-14.so.1 in the multiarch dir" 0 probe_in "$root"
root="$(fake_tree dev usr/lib/llvm-14/lib/libclang.so)"
check "libclang.so (libclang-dev)" 0 probe_in "$root"
root="$(fake_tree local usr/local/lib/libclang.so.17)"
check "libclang.so.17 in /usr/local/lib" 0 probe_in "$root"
root="$(fake_tree empty)"
check "empty tree" 1 probe_in "$root"
# LIBCLANG_PATH is honoured: a directory or the library file itself, even outside every
# standard directory; one holding only libclang-cpp does not count.
mkdir -p "$tmp/custom/lib" "$tmp/custom-cpp"
: >"$tmp/custom/lib/libclang.so.1"
: >"$tmp/custom-cpp/libclang-cpp.so.18"
check "LIBCLANG_PATH directory" 0 probe_in "$root" LIBCLANG_PATH="$tmp/custom/lib"
check "LIBCLANG_PATH file" 0 probe_in "$root" LIBCLANG_PATH="$tmp/custom/lib/libclang.so.1"
check "LIBCLANG_PATH with only libclang-cpp" 1 probe_in "$root" LIBCLANG_PATH="$tmp/custom-cpp"
got="$(probe_in "$(fake_tree both usr/lib/libclang.so)" LIBCLANG_PATH="$tmp/custom/lib")"
check "LIBCLANG_PATH searched first" 0 test "$got" = "$tmp/custom/lib/libclang.so.1"
# llvm-config's --libdir is searched (an LLVM outside the standard directories).
cat >"$tmp/llvm-config-custom" <<CFG
#!/bin/sh
[ "\$1" = --libdir ] && echo "$tmp/custom/lib"
CFG
chmod +x "$tmp/llvm-config-custom"
check "llvm-config --libdir" 0 probe_in "$root" LLVM_CONFIG_PATH="$tmp/llvm-config-custom"
check "LD_LIBRARY_PATH" 0 probe_in "$root" LD_LIBRARY_PATH="/nonexistent:$tmp/custom/lib"

# python3 venv: a python that cannot make a venv with pip (Debian without python3-venv) → missing.
cat >"$tmp/python-no-venv" <<'PY'
#!/bin/sh
[ "$1" = -m ] && [ "$2" = venv ] && { echo "ensurepip is not available" >&2; exit 1; }
exit 0
PY
chmod +x "$tmp/python-no-venv"
check "python without venv" 1 env PYTHON="$tmp/python-no-venv" bash -c '. "$0"; probe_python_venv' "$(dirname "$0")/lib/probes.sh"
check "no python at all" 1 env PYTHON=/nonexistent/python3 bash -c '. "$0"; probe_python_venv' "$(dirname "$0")/lib/probes.sh"
if command -v python3 >/dev/null 2>&1; then
  check "this machine's python3 makes a venv" 0 probe_python_venv
fi

# On this machine, after set-up, the probe must find what bindgen will load.
if [ -n "${OBJVIEW_PROBES_AFTER_SETUP:-}" ]; then
  check "this machine has libclang after set-up" 0 probe_find_libclang
fi

echo "probes: $pass passed, $fail failed"
[ "$fail" = 0 ]
