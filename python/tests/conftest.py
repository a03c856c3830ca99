"""Shared fixtures: the repository's samples and the `aptscope` binary (built when missing)."""

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "samples"


@pytest.fixture(scope="session")
def aptscope_bin() -> Path:
    """The command-line binary, to compare the package with (APTSCOPE_BIN, else built)."""
    env = os.environ.get("APTSCOPE_BIN")
    if env:
        return Path(env)
    subprocess.run(
        ["cargo", "build", "-q", "--bin", "aptscope"], cwd=REPO, check=True
    )
    return REPO / "target" / "debug" / "aptscope"


@pytest.fixture()
def samples() -> Path:
    return SAMPLES
