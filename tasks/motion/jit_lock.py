"""An inter-process lock around librosa analyses.

librosa compiles its numba kernels on first use, per argument types, and caches them next to its own
code (``cache=True``). Two processes compiling at once (pytest-xdist workers, DataLoader workers,
several ``sm`` runs on a fresh install) can read each other's half-written cache and crash with a
segmentation fault (reproduced here with two processes on a fresh virtual environment). Which kernels
a call compiles depends on its path (the tempo estimate runs only without a tempo prior), so every
analysis runs under an exclusive file lock: analyses of different processes are serialized (an
analysis' time: ``benchmarks/README.md``, "Toolkit"; results are cached on disk by :mod:`.cache`). Where
``fcntl`` is missing (Windows) the lock is a no-op.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["LOCK_PATH", "librosa_lock"]

LOCK_PATH = Path(tempfile.gettempdir()) / "skeleton_mamba_librosa_jit.lock"


@contextmanager
def librosa_lock() -> Iterator[None]:
    """Hold :data:`LOCK_PATH` exclusively for the duration of the block."""
    try:
        import fcntl  # lazy: POSIX only
    except ImportError:  # not POSIX
        yield
        return
    with LOCK_PATH.open("a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
