"""Checks on values read from files: finite numbers, frame rates in a sane range, sound ``.npy`` files.

Every reader of outside data calls :func:`check_finite` on the arrays it parsed, so a NaN, an Inf or
an overflow such as ``1e999`` in one file stops with a message naming the file and the first bad
entry instead of flowing into training. Frame rates outside :data:`FPS_RANGE` are refused: they are
corrupt headers, and allocations that scale with a rate (resampled frames, the renderer's smoothing
window) would be unbounded. :func:`load_npy` checks a ``.npy`` header against the file size before
anything is allocated.
"""

from __future__ import annotations

import math
import tokenize
from collections.abc import Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np

from skeleton_mamba.tasks.motion.errors import DataFileError

__all__ = ["FPS_RANGE", "check_finite", "check_fps", "load_npy", "non_finite_message", "read_npy_header"]

# What a damaged .npy header makes numpy raise (its header is a Python literal parsed by ast).
NPY_HEADER_ERRORS = (ValueError, OSError, EOFError, SyntaxError, tokenize.TokenError)

FPS_RANGE = (1.0, 1000.0)


def check_fps(fps: float, what: str = "frame rate") -> float:
    """``fps`` when it lies in :data:`FPS_RANGE`, else a ``ValueError`` naming ``what``."""
    if not (math.isfinite(fps) and FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        raise ValueError(f"{what} {fps:g} is outside {FPS_RANGE[0]:g}-{FPS_RANGE[1]:g} frames per second")
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


def read_npy_header(stream: BinaryIO) -> tuple[tuple[int, ...], np.dtype]:
    """``(shape, dtype)`` from the header of a ``.npy`` stream, leaving it at the first data byte.

    Raises:
        ValueError (or another of ``NPY_HEADER_ERRORS``): not a ``.npy`` header of version 1.0 or 2.0.
    """
    version = np.lib.format.read_magic(stream)
    if version not in ((1, 0), (2, 0)):
        raise ValueError(f"unsupported .npy format version {version}")
    fmt = np.lib.format
    shape, _, dtype = (fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0)(stream)
    return tuple(shape), dtype


def load_npy(path: str | Path) -> np.ndarray:
    """A ``.npy`` array whose header agrees with the file size (nothing is allocated from a bad header).

    Raises:
        FileNotFoundError: no such file.
        DataFileError: a damaged header, pickled objects, or fewer / more data bytes than the header says.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such .npy file")
    try:
        with open(path, "rb") as f:
            shape, dtype = read_npy_header(f)
            data_bytes = path.stat().st_size - f.tell()
    except NPY_HEADER_ERRORS as e:
        raise DataFileError(f"{path}: not a readable .npy file ({type(e).__name__}: {e})") from None
    if dtype.hasobject:
        raise DataFileError(f"{path}: holds Python objects (dtype {dtype}); only numeric arrays are read")
    expected = math.prod(shape) * dtype.itemsize
    if data_bytes != expected:
        raise DataFileError(f"{path}: the header says {shape} {dtype} ({expected} bytes) but {data_bytes} "
                            "bytes follow (truncated or damaged)")  # fmt: skip
    try:
        return np.load(path, allow_pickle=False)
    except NPY_HEADER_ERRORS as e:
        raise DataFileError(f"{path}: not a readable .npy file ({type(e).__name__}: {e})") from None
