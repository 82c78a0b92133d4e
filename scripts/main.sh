#!/usr/bin/env bash
# The main job (README "Run the main job"): set-up, release build, and `objview demo` on the
# built-in objects. Extra arguments go to `objview demo` (e.g. --out DIR).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
[ -f "$HOME/.cargo/env" ] && . "$HOME/.cargo/env"
cargo build --release --locked -p objview-cli
exec "${CARGO_TARGET_DIR:-target}/release/objview" demo "$@"
