#!/usr/bin/env bash
# Probes that decide what scripts/setup.sh installs. Each answers "is the thing a build or test
# step *loads* present?" the way that step itself looks for it, never by a loose file-name
# match (a loose `libclang*.so*` once matched the C++ library libclang-cpp and hid a missing
# libclang on every fresh machine). Sourced by setup.sh; tested by scripts/test-probes.sh
# against fake directory trees.
#
# Test hooks (empty in normal use): PROBE_ROOT prefixes every standard directory searched, and
# LLVM_CONFIG_PATH names the llvm-config to ask (as clang-sys itself honours it).

# True if NAME is a file name clang-sys (bindgen's loader) accepts for the libclang C library:
# libclang.so, libclang.so.N…, libclang-N….so, libclang-N….so.N… — never libclang-cpp*.
probe_is_libclang_name() {
  [[ "$1" =~ ^libclang(-[0-9][0-9.]*)?\.so(\.[0-9][0-9.]*)?$ ]]
}

# Prints the first libclang C library found in DIR (non-recursive); false if none.
probe_libclang_in_dir() {
  local dir="$1" f
  [ -d "$dir" ] || return 1
  for f in "$dir"/libclang*.so*; do
    [ -e "$f" ] || continue
    if probe_is_libclang_name "$(basename "$f")"; then
      echo "$f"
      return 0
    fi
  done
  return 1
}

# Prints the libclang C library bindgen would load, searching as clang-sys does: LIBCLANG_PATH
# (a directory or the library file itself), then `llvm-config --libdir` (LLVM_CONFIG_PATH or
# llvm-config on PATH), then LD_LIBRARY_PATH, then the usual system directories. False if none.
probe_find_libclang() {
  local root="${PROBE_ROOT:-}" dir cfg libdir
  if [ -n "${LIBCLANG_PATH:-}" ]; then
    if [ -f "$LIBCLANG_PATH" ] && probe_is_libclang_name "$(basename "$LIBCLANG_PATH")"; then
      echo "$LIBCLANG_PATH"
      return 0
    fi
    probe_libclang_in_dir "$LIBCLANG_PATH" && return 0
  fi
  cfg="${LLVM_CONFIG_PATH:-llvm-config}"
  if command -v "$cfg" >/dev/null 2>&1; then
    libdir="$("$cfg" --libdir 2>/dev/null || true)"
    if [ -n "$libdir" ]; then
      probe_libclang_in_dir "$libdir" && return 0
    fi
  fi
  local IFS_SAVE="$IFS"
  IFS=:
  for dir in ${LD_LIBRARY_PATH:-}; do
    IFS="$IFS_SAVE"
    [ -n "$dir" ] && probe_libclang_in_dir "$dir" && return 0
  done
  IFS="$IFS_SAVE"
  shopt -s nullglob
  local dirs=("$root"/usr/local/llvm*/lib* "$root"/usr/local/lib* "$root"/usr/local/lib*/*
    "$root"/usr/lib/llvm-*/lib "$root"/usr/lib* "$root"/usr/lib*/*)
  shopt -u nullglob
  for dir in "${dirs[@]}"; do
    probe_libclang_in_dir "$dir" && return 0
  done
  return 1
}

# True if python3 can make a virtual environment with pip in it, tried for real in a temporary
# folder (Debian splits `ensurepip` into python3-venv; `import venv` alone succeeds without it).
probe_python_venv() {
  local py="${PYTHON:-python3}" tmp ok=1
  command -v "$py" >/dev/null 2>&1 || return 1
  tmp="$(mktemp -d)"
  if "$py" -m venv "$tmp/venv" >/dev/null 2>&1 && "$tmp/venv/bin/python" -m pip --version >/dev/null 2>&1; then
    ok=0
  fi
  rm -rf "$tmp"
  return $ok
}
