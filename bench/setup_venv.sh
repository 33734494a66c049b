#!/usr/bin/env bash
# Create bench/.venv (if missing) with the pinned peers of the accuracy benchmark.
# Idempotent: does nothing when the venv already satisfies bench/requirements.txt.
# Usage: bench/setup_venv.sh            then: bench/.venv/bin/python bench/peers.py DIR
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv"
req="$here/requirements.txt"
py="${PYTHON:-python3}"

if [ ! -x "$venv/bin/python" ]; then
    "$py" -m venv "$venv" || { echo "setup_venv: '$py -m venv' failed (install python3-venv?)" >&2; exit 1; }
fi

# Fast path: every pinned requirement already installed at its version.
if "$venv/bin/python" - "$req" <<'PY' 2>/dev/null; then exit 0; fi
import sys
from importlib.metadata import version, PackageNotFoundError
for line in open(sys.argv[1]):
    line = line.split("#")[0].strip()
    if not line:
        continue
    name, want = line.split("==")
    try:
        if version(name) != want:
            sys.exit(1)
    except PackageNotFoundError:
        sys.exit(1)
PY

log="$(mktemp)"
trap 'rm -f "$log"' EXIT
if ! "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
        --only-binary=:all: -r "$req" >"$log" 2>&1; then
    echo "setup_venv: pip could not install the pinned peers from $req:" >&2
    cat "$log" >&2
    exit 1
fi
"$venv/bin/python" -c "import numpy, cv2, libCBDetect, chess_corners, calib_targets" \
    || { echo "setup_venv: installed, but a peer fails to import" >&2; exit 1; }
echo "setup_venv: $venv ready"
