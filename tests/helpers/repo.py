"""Paths of the repository and its shared sample data, for tests and their helpers."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"


def load_script(relative: str):
    """The module of a script of the repository that is not in the package (``benchmarks/NAME.py``)."""
    import importlib.util

    path = REPO_ROOT / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def shared_file(relative: str) -> Path:
    """One file of ``../shared/data``, skipping the calling test with a clear reason when absent."""
    path = SHARED_DATA / relative
    if not path.exists():
        pytest.skip(f"real sample {relative} not found under {SHARED_DATA}")
    return path
