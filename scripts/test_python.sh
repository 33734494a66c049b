#!/usr/bin/env bash
# Builds and tests the Python package `conic_corners` (crates/conic-corners-py):
#   1. a venv at target/py-venv (created once, reused), with pytest, numpy and
#      opencv-python-headless (a test dependency only);
#   2. `pip install ./crates/conic-corners-py` (maturin, pulled by pip from the pyproject's
#      build-system, builds the extension in release mode into the workspace's target/);
#   3. the CLI (`cargo build --release -p conic-corners-cli`), against which results are compared;
#   4. pytest on crates/conic-corners-py/tests.
# Extra arguments go to pytest. PYTHON selects the interpreter (default python3, ≥ 3.9).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
PYTHON="${PYTHON:-python3}"
VENV="$ROOT/target/py-venv"
PY="$VENV/bin/python"

step() { printf '\n== %s (%ss)\n' "$1" "$SECONDS"; }

step "venv $VENV"
if ! "$PY" -c "import sys; assert sys.version_info >= (3, 9)" 2>/dev/null; then
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
fi
"$PY" -m pip install --quiet --disable-pip-version-check --upgrade pip
"$PY" -m pip install --quiet --disable-pip-version-check pytest numpy opencv-python-headless

step "pip install ./crates/conic-corners-py"
# A local path is always rebuilt (incrementally, in target/), so edits are picked up.
"$PY" -m pip install --quiet --disable-pip-version-check ./crates/conic-corners-py

step "cargo build --release -p conic-corners-cli"
cargo build --release --quiet -p conic-corners-cli
export CONIC_CORNERS_BIN="${CONIC_CORNERS_BIN:-$ROOT/target/release/conic-corners}"

step "pytest"
# Run from the tests folder so `import conic_corners` is the installed package.
cd "$ROOT/crates/conic-corners-py/tests"
"$PY" -m pytest -q -rs "$@" .
echo "test_python.sh: done in ${SECONDS}s"
