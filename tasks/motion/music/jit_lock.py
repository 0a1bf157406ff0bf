"""librosa's numba kernels: a cache folder of the project's own, compiled one process at a time.

librosa compiles its numba kernels (at import for those with explicit signatures, else on first use, per
argument types) and caches them on disk (``cache=True``), by default next to its own code, where every
program of the environment shares them. Two processes compiling at once (two ``sm`` runs, pytest-xdist
or DataLoader workers, ``sm`` beside another program using librosa) can read each other's half-written
cache files; the cache they leave can make every later analysis in that environment die with a
segmentation fault and no message (``peak_pick``, ``piptrack``) until the files are deleted. So:

- :func:`librosa_calls` points numba's cache at :func:`numba_cache_dir` (``<cache root>/numba``, see
  :func:`~skeleton_mamba.tasks.motion.io.cache.default_cache_root`), unless the user set ``NUMBA_CACHE_DIR``,
  before librosa (and numba) is first imported; no other program writes there;
- it imports librosa and runs the block holding an exclusive file lock (:func:`lock_path`, in that
  folder), so the project's analyses in different processes compile, load and run their kernels one at a
  time (an analysis' time: ``benchmarks/README.md``, "Toolkit"; results are cached on disk by
  :mod:`skeleton_mamba.tasks.motion.io.cache`). Every librosa call of the project runs inside it. Where
  ``fcntl`` is missing (Windows) the lock is a no-op.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from types import ModuleType

from skeleton_mamba.tasks.motion.io.cache import default_cache_root

__all__ = [
    "NUMBA_CACHE_ENV",
    "librosa_calls",
    "librosa_lock",
    "librosa_version",
    "lock_path",
    "numba_cache_dir",
]

NUMBA_CACHE_ENV = "NUMBA_CACHE_DIR"
_LOCK_NAME = ".skeleton_mamba_compile.lock"
_held = threading.local()  # this thread's depth of nested librosa_lock blocks
_warm_paths: set[str] = set()  # librosa_calls' warm paths that ran once in this process


def numba_cache_dir() -> Path:
    """The folder numba caches librosa's kernels in: the user's ``NUMBA_CACHE_DIR`` if set, else the
    project's own ``<cache root>/numba``."""
    env = os.environ.get(NUMBA_CACHE_ENV)
    return Path(env).expanduser() if env else default_cache_root() / "numba"


def lock_path() -> Path:
    """The lock file every librosa call of the project holds (inside :func:`numba_cache_dir`)."""
    return numba_cache_dir() / _LOCK_NAME


def _point_numba_cache() -> None:
    """Set ``NUMBA_CACHE_DIR`` to :func:`numba_cache_dir` unless the user set it (numba reads it when
    imported; an already imported numba is told to read it again)."""
    if os.environ.get(NUMBA_CACHE_ENV):
        return
    os.environ[NUMBA_CACHE_ENV] = str(numba_cache_dir())
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.reload_config()


@contextmanager
def librosa_lock() -> Iterator[None]:
    """Hold :func:`lock_path` exclusively for the duration of the block (numba's cache pointed at the
    project's folder first); a block inside another of the same thread holds it already."""
    _point_numba_cache()
    depth = getattr(_held, "depth", 0)
    try:
        import fcntl  # lazy: POSIX only
    except ImportError:  # not POSIX
        fcntl = None
    if depth or fcntl is None:
        _held.depth = depth + 1
        try:
            yield
        finally:
            _held.depth = depth
        return
    path = lock_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        _held.depth = 1
        try:
            yield
        finally:
            _held.depth = 0
            fcntl.flock(handle, fcntl.LOCK_UN)


@contextmanager
def librosa_calls(warm_path: str | None = None) -> Iterator[ModuleType]:
    """``with librosa_calls() as librosa: ...``: librosa, imported and used under :func:`librosa_lock`.

    ``warm_path``: a name for a call path that runs the same librosa calls on the same types every time (a
    live stream's per-frame features): it holds the lock on its first run in a process, which imports librosa
    and compiles whatever those calls compile, and not after, so a long analysis in another process never
    stalls a live stream.
    """
    if warm_path is not None and warm_path in _warm_paths:
        import librosa  # lazy: imported (under the lock) on the path's first run

        yield librosa
        return
    with librosa_lock():
        import librosa  # lazy: librosa's import is slow (numba), and compiles kernels

        yield librosa
    if warm_path is not None:
        _warm_paths.add(warm_path)


def librosa_version() -> str:
    """The installed librosa's version (for cache keys), read without importing it."""
    return metadata.version("librosa")
