#!/usr/bin/env bash
# The paper's single-corner accuracy benchmark (section IV-A), conic-corners and peers on the same
# images in one run:
#   bash bench/accuracy.sh [OUT_DIR] [PER_POINT]
# 1. renders the noise / blur / perspective / curvature sweeps with fixed seeds (PER_POINT images
#    per sweep point, default 200) as 8-bit PNGs and runs conic-corners on them (Rust, release);
# 2. runs the peers (OpenCV, libcbdetect, chess-corners) from the venv bench/.venv it creates;
# 3. prints the table (MLE over successes, success rate, Cramér–Rao bound, ratio to the best peer)
#    and writes it as markdown to OUT_DIR/report.md.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-bench/out/accuracy}
per_point=${2:-200}
jobs=${JOBS:-$(nproc)}
cargo build --release --locked -p conic-corners-bench
./target/release/accuracy --out "$out" --per-point "$per_point"
bash bench/setup_venv.sh
bench/.venv/bin/python bench/peers.py "$out" --jobs "$jobs"
bench/.venv/bin/python bench/report.py "$out"
bench/.venv/bin/python bench/report.py "$out" --markdown > "$out/report.md"
echo "markdown table: $out/report.md" >&2
