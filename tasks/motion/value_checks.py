"""Checks on values read from files: finite numbers, frame rates in a sane range.

Every reader of outside data calls :func:`check_finite` on the arrays it parsed, so a NaN, an Inf or
an overflow such as ``1e999`` in one file stops with a message naming the file and the first bad
entry instead of flowing into training. Frame rates outside :data:`FPS_RANGE` are refused: they are
corrupt headers, and allocations that scale with a rate (resampled frames, the renderer's smoothing
window) would be unbounded.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from skeleton_mamba.tasks.errors import DataFileError

__all__ = ["FPS_RANGE", "check_finite", "check_fps", "non_finite_message"]

FPS_RANGE = (1.0, 1000.0)


def check_fps(fps: float, what: str = "frame rate") -> float:
    """``fps`` when it lies in :data:`FPS_RANGE`, else a ``ValueError`` naming ``what``."""
    if not (math.isfinite(fps) and FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        raise ValueError(f"{what} {fps} is outside {FPS_RANGE[0]:g}-{FPS_RANGE[1]:g} frames per second")
    return fps


def non_finite_message(array: np.ndarray, what: str, axes: Sequence[str] = ()) -> str | None:
    """A description of the first non-finite entry of ``array``, or ``None`` when all are finite.

    Args:
        array: any numeric array (integers are always finite).
        what: the array's name in the message (``"joints"``).
        axes: names of the leading axes (``("frame", "joint")``); indices are 0-based.

    Returns:
        e.g. ``"joints: nan at frame 12, joint 3 (0-based; 2 non-finite values)"``.
    """
    array = np.asarray(array)
    if not np.issubdtype(array.dtype, np.inexact):
        return None
    bad = ~np.isfinite(array)
    if not bad.any():
        return None
    first = np.unravel_index(int(np.argmax(bad)), array.shape)
    named = [f"{name} {i}" for name, i in zip(axes, first)] or [f"index {tuple(int(i) for i in first)}"]
    return f"{what}: {array[first]} at {', '.join(named)} (0-based; {int(bad.sum())} non-finite values)"


def check_finite(
    array: np.ndarray,
    source: str,
    what: str,
    axes: Sequence[str] = (),
    error: type[DataFileError] = DataFileError,
) -> np.ndarray:
    """Return ``array`` when every entry is finite, else raise ``error`` naming ``source`` and the entry.

    Args:
        array: the parsed values.
        source: the file (or ``file: key``) the values come from.
        what, axes: see :func:`non_finite_message`.
        error: the reader's own :class:`DataFileError` subclass.
    """
    message = non_finite_message(array, what, axes)
    if message is not None:
        raise error(f"{source}: {message}")
    return array
