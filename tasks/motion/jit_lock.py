"""An inter-process lock around each process's first librosa analysis.

librosa compiles its numba kernels on first use and caches them next to its own code
(``cache=True``). Two processes compiling at once (pytest-xdist workers, DataLoader workers, several
``sm`` runs on a fresh install) can read each other's half-written cache and crash with a
segmentation fault (reproduced here with two processes on a fresh virtual environment). The first
analysis of every process therefore runs under an exclusive file lock; once it has run, the kernels
are loaded in that process and later calls skip the lock. Where ``fcntl`` is missing (Windows) the
lock is a no-op.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["LOCK_PATH", "first_librosa_call_lock"]

LOCK_PATH = Path(tempfile.gettempdir()) / "skeleton_mamba_librosa_jit.lock"
_warm = False


@contextmanager
def first_librosa_call_lock() -> Iterator[None]:
    """Hold :data:`LOCK_PATH` exclusively during this process's first librosa analysis."""
    global _warm
    if _warm:
        yield
        return
    try:
        import fcntl
    except ImportError:  # not POSIX
        fcntl = None
    with LOCK_PATH.open("a") as handle:
        if fcntl is not None:
            fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
            _warm = True
        finally:
            if fcntl is not None:
                fcntl.flock(handle, fcntl.LOCK_UN)
