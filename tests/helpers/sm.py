"""Running ``sm`` as a user does, in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest


def sm_executable() -> str:
    """The installed ``sm`` console script next to this interpreter."""
    path = Path(sys.executable).with_name("sm")
    if not path.exists():
        pytest.skip(f"console script not installed at {path}")
    return str(path)


def run_sm(args: list[str], cwd: Path, timeout: int = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "ignore"}
    return subprocess.run(
        [sm_executable(), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )
