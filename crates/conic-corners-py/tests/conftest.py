import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def cli_bin() -> str:
    """The `conic-corners` CLI: $CONIC_CORNERS_BIN or target/release/conic-corners."""
    path = os.environ.get("CONIC_CORNERS_BIN") or str(REPO / "target" / "release" / "conic-corners")
    if not (Path(path).is_file() and os.access(path, os.X_OK)):
        pytest.skip(
            f"CLI binary not found at {path}: build it with "
            "`cargo build --release -p conic-corners-cli` or set CONIC_CORNERS_BIN"
        )
    return path


def cli_has(cli: str, subcommand: str) -> bool:
    return subprocess.run([cli, subcommand, "--help"], capture_output=True).returncode == 0
