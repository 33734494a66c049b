#!/usr/bin/env bash
# The whole test suite: every Rust test of the workspace (unit, integration, CLI, doc tests), then
# the Python package's tests (scripts/test_python.sh builds it into a venv under target/), then
# clippy on every target with warnings as errors (skipped, with a note, where clippy is missing).
# `.ci/run` calls exactly this script; the README's second set-up command runs it too.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --release --workspace --locked
bash scripts/test_python.sh
if cargo clippy --version >/dev/null 2>&1; then
    cargo clippy --release --workspace --all-targets --locked -- -D warnings
else
    echo "test.sh: cargo clippy is not installed; lints skipped" >&2
fi
