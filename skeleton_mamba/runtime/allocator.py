"""glibc ``malloc`` settings: the memory a training step or a streamed frame frees stays in the heap.

A CPU training step allocates and frees hundreds of MB of tensors of 0.1 to 30 MB each. By default glibc
serves blocks above its *mmap threshold* by a fresh ``mmap`` and returns the top of the heap to the system
once more than its *trim threshold* lies free there; both thresholds adapt to the sizes freed, but only up
to 32 MiB and 64 MiB. Every step then writes to new pages, which the kernel hands out zero-filled, one
page fault each: thousands of minor page faults per training step, and a share of the step spent in the
kernel. With the mmap threshold fixed at 32 MiB (the most glibc's own adaptation reaches) and the trim
threshold at 1 GiB the faults and the kernel time are gone (the figures: ``benchmarks/README.md``, "Faster
demo step"). The results are bit-identical: only where the memory comes from changes.

A streamed frame (:func:`skeleton_mamba.runtime.streaming.step`) allocates and frees the same few hundred kB
buffers every frame; with the adaptive defaults a frame could start with thousands of minor page faults,
none with these settings (``benchmarks/README.md``, "Streaming").

The cost: a process that went through a peak keeps that memory resident (it is reused, not returned),
which a training run does anyway from its first step on. So ``sm fit|validate|test|predict`` and the
frame-by-frame commands (``sm stream``) set this (:func:`keep_freed_memory`), the others do not (``sm
dance``'s memory must fall back after a long video). Nothing is changed where the user chose these malloc
settings (``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_``, ``MALLOC_TOP_PAD_`` or
``GLIBC_TUNABLES``), nor off glibc (macOS, Windows, musl): there the call does nothing and returns False.
"""

from __future__ import annotations

import ctypes
import os
import platform
from collections.abc import Mapping

__all__ = ["MMAP_THRESHOLD", "TRIM_THRESHOLD", "keep_freed_memory"]

# mallopt(3) parameters (malloc.h) and the values set.
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD = 32 << 20
"""Blocks of at least this size are mapped, smaller ones come from the heap (the most glibc adapts to)."""
TRIM_THRESHOLD = 1 << 30
"""The heap's top is returned to the system only when more than this lies free there."""

_USER_VARIABLES = ("GLIBC_TUNABLES", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_")


def keep_freed_memory(environ: Mapping[str, str] | None = None) -> bool:
    """Set glibc's mmap and trim thresholds for this process (module docstring).

    >>> keep_freed_memory({"MALLOC_TRIM_THRESHOLD_": "1"})  # the user's own setting: left alone
    False

    Returns True when both were set; False (and nothing changed) off glibc, when ``environ`` (default
    ``os.environ``) holds the user's own malloc settings, or when glibc refuses a value.
    """
    environ = os.environ if environ is None else environ
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    if any(name in environ for name in _USER_VARIABLES):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    # The mmap threshold first: setting the trim threshold alone freezes the mmap threshold at its
    # 128 kB start, and then every block above that is a fresh mapping.
    return mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1 and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
