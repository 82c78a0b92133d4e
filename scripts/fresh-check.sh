#!/usr/bin/env bash
# Fresh-machine check: runs one of the README's two commands from a fresh clone of this
# repository's HEAD, with an empty cargo target directory and no Python virtual environment,
# and prints how long it took. Use it before a release and after changing dependencies or
# scripts/setup.sh: a green CI on a developer's machine can hide a missing install step.
#
#   bash scripts/fresh-check.sh [--main] [--remove-installed] [--keep-clone]
#
#   --main               run `bash scripts/main.sh` (the main job) instead of scripts/test.sh
#   --remove-installed   DESTRUCTIVE, root on a throw-away machine only: first purge the system
#                        packages that scripts/setup.sh installs (cmake, libclang-dev and what
#                        apt installed with them), so that set-up is exercised as on a new machine
#   --keep-clone         keep the temporary clone (and its target directory) afterwards
# Never run with --remove-installed in CI or on a machine you care about.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
cmd=scripts/test.sh
remove=0
keep=0
for arg in "$@"; do
  case "$arg" in
    --main) cmd=scripts/main.sh ;;
    --remove-installed) remove=1 ;;
    --keep-clone) keep=1 ;;
    --) ;;
    *) echo "fresh-check: unknown argument $arg (see the comment at the top)" >&2; exit 2 ;;
  esac
done

if [ "$remove" = 1 ]; then
  if [ -n "${CI:-}" ]; then
    echo "fresh-check: --remove-installed refuses to run in CI" >&2
    exit 2
  fi
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "fresh-check: --remove-installed needs root and apt-get" >&2
    exit 2
  fi
  echo "fresh-check: purging cmake and libclang-dev (and their automatically installed dependencies)"
  DEBIAN_FRONTEND=noninteractive apt-get purge -y -qq cmake libclang-dev >/dev/null 2>&1 || true
  DEBIAN_FRONTEND=noninteractive apt-get autoremove --purge -y -qq >/dev/null 2>&1 || true
fi
echo "fresh-check: set-up would install: $(OBJVIEW_SETUP_DRY_RUN=1 bash "$repo/scripts/setup.sh")"

work="$(mktemp -d)"
if [ "$keep" = 0 ]; then
  trap 'rm -rf "$work"' EXIT
fi
git clone -q "$repo" "$work/objview"
echo "fresh-check: clone of $(git -C "$repo" rev-parse --short HEAD) in $work/objview; running $cmd"
start=$(date +%s)
status=0
(cd "$work/objview" && env -u CARGO_TARGET_DIR -u OBJVIEW_BIN -u OBJVIEW_VENV bash "$cmd") || status=$?
end=$(date +%s)
secs=$((end - start))
echo "fresh-check: $cmd exited $status after ${secs} s ($((secs / 60)) min $((secs % 60)) s) on $(nproc) cores"
exit $status
