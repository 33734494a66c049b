#!/usr/bin/env bash
# The whole test suite: every Rust test of the workspace (unit, integration, CLI, doc tests), then
# the Python package's tests (scripts/test_python.sh builds it into a venv under target/).
# `.ci/run` calls exactly this script; the README's second set-up command runs it too.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --release --workspace --locked
bash scripts/test_python.sh
