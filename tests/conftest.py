"""Shared test fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

# The suite runs under pytest-xdist with one worker per core: one intra-op thread per worker
# avoids oversubscription, which slows small ops down by an order of magnitude.
torch.set_num_threads(1)

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real sample files in ``../shared/data`` (skips the test when the folder is absent)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real sample data not found at {SHARED_DATA} (the project's shared/data folder)")
    return SHARED_DATA


def shared_file(relative: str) -> Path:
    """One file of ``../shared/data``, skipping the calling test with a clear reason when absent."""
    path = SHARED_DATA / relative
    if not path.exists():
        pytest.skip(f"real sample {relative} not found under {SHARED_DATA}")
    return path
