#!/usr/bin/env bash
# The curved-board accuracy benchmark (paper Table I) and stereo triangulation (experiment IV-B),
# conic-corners and its peers on the same images in one run:
#   bash bench/board_accuracy.sh [OUT_DIR] [N_PAIRS] [board-accuracy options...]
# 1. builds board-accuracy (release), renders N_PAIRS (default 40) stereo pairs of boards bent
#    around cylinders, elliptic columns and S shapes (and some flat ones) with fixed seeds as 8-bit
#    PNGs plus truth (OUT_DIR/truth.jsonl), and runs conic-corners on them in both refine modes
#    (OUT_DIR/ours.jsonl);
# 2. runs the peers (OpenCV, libcbdetect, calib-targets, chess-corners) from the venv bench/.venv
#    it creates, JOBS (default 2) views at a time (OUT_DIR/peers.jsonl);
# 3. prints the tables and writes them as markdown, with the command and commit, to
#    OUT_DIR/report.md.
# A full run of 40 pairs takes about 15 min on 2 cores, mostly the peers (OpenCV's
# findChessboardCorners can take minutes on a curved board it fails on: board_peers.py gives every
# method at most 120 s per view). Options after N_PAIRS go to board-accuracy, e.g.
# `--occluded-share 0.5` (a bar across the board in half the views: findChessboardCorners then
# mostly runs into its timeout) or `--seed 7`.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-bench/out/board_accuracy}
pairs=${2:-40}
shift $(( $# < 2 ? $# : 2 ))
jobs=${JOBS:-2}
cmd="bash bench/board_accuracy.sh $out $pairs${*:+ $*}"
start=$(date +%s)
commit=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
git diff --quiet HEAD 2>/dev/null || commit="$commit (with uncommitted changes)"
cargo build --release --locked -p conic-corners-bench --bin board-accuracy
./target/release/board-accuracy --out "$out" --pairs "$pairs" "$@"
bash bench/setup_venv.sh
bench/.venv/bin/python bench/board_peers.py "$out" --jobs "$jobs"
bench/.venv/bin/python bench/board_report.py "$out"
{
    took=$(( $(date +%s) - start ))
    echo "Command: \`$cmd\` (JOBS=$jobs) at commit $commit, $(date -u +%Y-%m-%d), $took s."
    echo
    bench/.venv/bin/python bench/board_report.py "$out" --markdown
} > "$out/report.md"
echo "markdown tables: $out/report.md" >&2
