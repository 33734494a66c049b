#!/usr/bin/env bash
# Speed of board detection, conic-corners and its peers on the same images in one run
# (issue "Board detection", item 8):
#   bash bench/detect_speed.sh [OUT_DIR] [RUNS]
# 1. builds the release CLI and render-board, renders the 1920x1200 flat 9x9-corner board
#    (OUT_DIR/board.png + board.json, fixed seeds);
# 2. times every method single-threaded on it and on ../shared/images/curved-hydramarker/curve_6.jpg
#    (skipped when missing), median of RUNS (default 10) after a warm-up, from the venv
#    bench/.venv it creates;
# 3. prints the table and writes it as markdown to OUT_DIR/report.md (rows also in report.json).
# Extra arguments after RUNS go to detect_speed.py (e.g. --budget 0 for RUNS runs of every peer).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-bench/out/speed}
runs=${2:-10}
shift $(( $# < 2 ? $# : 2 ))
export RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1
cargo build --release --locked -p conic-corners-cli -p conic-corners-bench
mkdir -p "$out"
./target/release/render-board --png "$out/board.png" --truth "$out/board.json"
bash bench/setup_venv.sh
args=(--cli target/release/conic-corners --board "$out/board.png" --truth "$out/board.json"
      --curve ../shared/images/curved-hydramarker/curve_6.jpg --runs "$runs" "$@")
bench/.venv/bin/python bench/detect_speed.py "${args[@]}" --json "$out/report.json" \
    --markdown-out "$out/report.md"
echo "markdown table: $out/report.md" >&2
