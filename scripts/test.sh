#!/usr/bin/env bash
# The whole test suite (README "Run the tests"): set-up, formatting, lints, unit and
# end-to-end tests. CI runs exactly this through .ci/run.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
[ -f "$HOME/.cargo/env" ] && . "$HOME/.cargo/env"

echo "== set-up probes (fake trees, and this machine after set-up)"
OBJVIEW_PROBES_AFTER_SETUP=1 bash scripts/test-probes.sh

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy"
# Same profile as the tests, so the C++ solver (HiGHS) that a build script compiles is built once.
cargo clippy --workspace --all-targets --locked --profile ci -- -D warnings
echo "== cargo doc (no warnings: broken or private intra-doc links, stray brackets and tags)"
# After clippy, whose dependency metadata it reuses: only the workspace's crates are documented.
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --locked --profile ci
echo "== cargo test"
# The learned-data test keeps the dataset it wrote for the Python loader's contract test.
learn_data="$(mktemp -d)/learn-dataset"
OBJVIEW_KEEP_LEARN_DATASET="$learn_data" cargo test --workspace --locked --profile ci
echo "== python client and Gymnasium env (pytest against a real objview serve)"
# `cargo test` above built the binary the CLI tests use; the Python suite starts it as a server.
# The path must be absolute: run_tests.sh runs pytest from python/tests.
target_dir="${CARGO_TARGET_DIR:-target}"
case "$target_dir" in /*) ;; *) target_dir="$PWD/$target_dir" ;; esac
OBJVIEW_LEARN_DATASET="$learn_data" OBJVIEW_BIN="${OBJVIEW_BIN:-$target_dir/ci/objview}" bash python/run_tests.sh
