"""On-disk cache for per-file feature arrays (music features, pretrained audio embeddings).

An entry is keyed by the SHA-256 of the input file's *content* and a JSON dump of the settings that
produced it, so renaming or moving a file keeps its cache entry while editing it (or changing any setting)
misses. Entries are ``.npy`` files written atomically: the array goes to a temporary file in the cache
folder, is flushed to disk and then renamed over the final name with :func:`os.replace`, so a crash never
leaves a half-written entry behind. Arrays are saved and loaded with pickling disabled.

The default folder is ``~/.cache/skeleton_mamba/<namespace>``; the environment variable
``SKELETON_MAMBA_CACHE`` moves the root, and every function takes an explicit ``cache_dir``.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from skeleton_mamba.io.atomic import atomic_open

__all__ = ["FeatureCache", "default_cache_root", "file_sha256"]

_CHUNK = 1 << 20


def default_cache_root() -> Path:
    """``$SKELETON_MAMBA_CACHE`` if set, else ``~/.cache/skeleton_mamba``."""
    env = os.environ.get("SKELETON_MAMBA_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "skeleton_mamba"


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes (read in 1 MiB chunks)."""
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            while chunk := f.read(_CHUNK):
                digest.update(chunk)
    except OSError as err:
        raise FileNotFoundError(f"{path}: cannot read the file to hash it ({err})") from err
    return digest.hexdigest()


class FeatureCache:
    """A folder of ``.npy`` arrays keyed by (file content hash, settings).

    Args:
        namespace: sub-folder under the cache root, e.g. ``"music"``.
        cache_dir: explicit folder (overrides root and namespace); ``None`` for the default.
        enabled: ``False`` turns every lookup into a miss and every store into a no-op.
    """

    def __init__(self, namespace: str, cache_dir: str | os.PathLike | None = None, enabled: bool = True):
        self.dir = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_root() / namespace
        self.enabled = enabled
        self.hits = 0
        self.misses = 0

    def key(self, path: str | os.PathLike, settings: dict[str, Any]) -> str:
        """Cache key: ``<content sha256>-<sha256 of the sorted settings JSON, 16 hex>``."""
        blob = json.dumps(settings, sort_keys=True, default=str).encode()
        return f"{file_sha256(path)}-{hashlib.sha256(blob).hexdigest()[:16]}"

    def path_for(self, key: str) -> Path:
        return self.dir / f"{key}.npy"

    def load(self, key: str) -> np.ndarray | None:
        """The cached array for ``key``, or ``None`` on a miss (a corrupt entry counts as a miss)."""
        if not self.enabled:
            self.misses += 1
            return None
        path = self.path_for(key)
        if not path.is_file():
            self.misses += 1
            return None
        try:
            array = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as err:
            warnings.warn(f"{path}: unreadable cache entry ({err}); recomputing", stacklevel=2)
            self.misses += 1
            return None
        self.hits += 1
        return array

    def store(self, key: str, array: np.ndarray) -> Path | None:
        """Write ``array`` atomically under ``key``; returns the entry path (``None`` when disabled)."""
        if not self.enabled:
            return None
        final = self.path_for(key)
        with atomic_open(final, "wb") as f:
            np.save(f, np.ascontiguousarray(array), allow_pickle=False)
        return final
