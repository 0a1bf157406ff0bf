"""Checks on values read from files: finite numbers, frame rates in a sane range, sound ``.npy`` files.

Every reader of outside data calls :func:`check_finite` on the arrays it parsed, so a NaN, an Inf or
an overflow such as ``1e999`` in one file stops with a message naming the file and the first bad
entry instead of flowing into training. Frame rates outside :data:`FPS_RANGE` are refused: they are
corrupt headers, and allocations that scale with a rate (resampled frames, the renderer's smoothing
window) would be unbounded. :func:`load_npy` checks a ``.npy`` header against the file size before
anything is allocated, and :func:`load_npz` checks every ``.npz`` member's array header against
:data:`MAX_NPZ_MEMBER_BYTES` before inflating it (a zip bomb stops at the bound, whatever the zip directory
claims). :func:`check_real` refuses complex, datetime, object, string and other non-real dtypes, and
:func:`check_magnitude` implausible values (positions beyond :data:`MAX_POSITION_M` metres), each naming the
file and the key.
"""

from __future__ import annotations

import math
import tokenize
import zipfile
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.tasks.motion.io.option_types import FPS_RANGE  # the bound of options and files alike

__all__ = [
    "FPS_RANGE",
    "MAX_NPZ_MEMBER_BYTES",
    "MAX_NPZ_MEMBERS",
    "MAX_POSITION_M",
    "check_finite",
    "check_fps",
    "check_magnitude",
    "check_real",
    "load_npy",
    "load_npz",
    "non_finite_message",
    "read_npy_header",
]

# What a damaged .npy header makes numpy raise (its header is a Python literal parsed by ast).
NPY_HEADER_ERRORS = (ValueError, OSError, EOFError, SyntaxError, tokenize.TokenError)

MAX_NPZ_MEMBER_BYTES = 1 << 30  # one array of an .npz, inflated: at most 1 GiB
MAX_NPZ_MEMBERS = 256  # arrays in one .npz
MAX_POSITION_M = 1e6  # |coordinate| of a position in metres beyond this is a corrupt or hostile file
REAL_KINDS = "biuf"  # numpy kinds of real numbers: bool, signed / unsigned integers, floats


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
        what: see :func:`non_finite_message`.
        axes: see :func:`non_finite_message`.
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
    shape, _, dtype = _npy_header(stream)
    return shape, dtype


def _npy_header(stream: BinaryIO) -> tuple[tuple[int, ...], bool, np.dtype]:
    """``(shape, fortran_order, dtype)`` of a ``.npy`` stream's header (versions 1.0 and 2.0)."""
    version = np.lib.format.read_magic(stream)
    if version not in ((1, 0), (2, 0)):
        raise ValueError(f"unsupported .npy format version {version}")
    fmt = np.lib.format
    read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
    shape, fortran, dtype = read(stream)
    return tuple(shape), bool(fortran), dtype


def load_npy(path: str | Path) -> np.ndarray:
    """A ``.npy`` array whose header agrees with the file size (nothing is allocated from a bad header).

    Raises:
        FileNotFoundError: no such file.
        DataFileError: a damaged header, pickled objects, or fewer / more data bytes than the header says.

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "joints.npy"
        >>> np.save(path, np.zeros((5, 24, 3), np.float32))
        >>> load_npy(path).shape
        (5, 24, 3)
        >>> _ = path.write_bytes(path.read_bytes()[:-4])  # truncated: fewer data bytes than its header says
        >>> load_npy(path)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        skeleton_mamba.errors.DataFileError: ...joints.npy: ...
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


def check_real(
    array: np.ndarray, source: str, what: str, error: type[DataFileError] = DataFileError
) -> np.ndarray:
    """``array`` when its dtype holds real numbers (bool, integers, floats), else ``error`` naming
    ``source`` and ``what`` (complex, datetime, timedelta, object, string and structured dtypes are refused
    rather than cast, which would drop imaginary parts or reinterpret dates)."""
    dtype = np.asarray(array).dtype
    if dtype.kind not in REAL_KINDS or dtype.fields is not None:
        raise error(f"{source}: {what!r} must hold real numbers, got dtype {dtype}")
    return array


def check_magnitude(
    array: np.ndarray,
    bound: float,
    source: str,
    what: str,
    axes: Sequence[str] = (),
    error: type[DataFileError] = DataFileError,
    unit: str = "",
) -> np.ndarray:
    """``array`` when every ``|entry| <= bound``, else ``error`` naming ``source``, ``what`` and the first
    offending entry (``axes`` name its leading indices, 0-based). Non-finite entries are left to
    :func:`check_finite`."""
    values = np.asarray(array)
    if values.size == 0 or not np.issubdtype(values.dtype, np.number):
        return array
    with np.errstate(invalid="ignore"):
        bad = np.abs(values.astype(np.float64, copy=False)) > bound
    if not bad.any():
        return array
    first = np.unravel_index(int(np.argmax(bad)), values.shape)
    named = [f"{name} {i}" for name, i in zip(axes, first)] or [f"index {tuple(int(i) for i in first)}"]
    raise error(f"{source}: {what}: {float(values[first]):g}{unit} at {', '.join(named)} (0-based) is beyond "
                f"the plausible {bound:g}{unit} ({int(bad.sum())} such values)")  # fmt: skip


def load_npz(
    path: str | Path,
    error: type[DataFileError] = DataFileError,
    text_keys: Sequence[str] = (),
    max_member_bytes: int = MAX_NPZ_MEMBER_BYTES,
) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file, each header checked before its member is inflated.

    Every ``.npy`` member's header must describe a real-number array (:func:`check_real`; the keys in
    ``text_keys`` may also hold strings) of at most ``max_member_bytes`` bytes; exactly that many bytes are
    inflated and the member must end there, so a zip bomb (a member inflating to gigabytes) or a directory
    that lies about sizes stops at the bound. Members other than ``.npy`` are ignored, as ``np.load`` does.

    Raises:
        FileNotFoundError: no such file.
        error: not a zip of ``.npy`` members, a refused dtype or size, a truncated or damaged member (the
            message names the file and the key).

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "clip.npz"
        >>> np.savez_compressed(path, fps=30.0, skeleton="smpl24", joints=np.zeros((5, 24, 3)))
        >>> arrays = load_npz(path, text_keys=("skeleton",))
        >>> sorted(arrays), str(arrays["skeleton"]), arrays["joints"].shape
        (['fps', 'joints', 'skeleton'], 'smpl24', (5, 24, 3))
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such .npz file")
    arrays: dict[str, np.ndarray] = {}
    unreadable = (zipfile.BadZipFile, zlib.error, NotImplementedError, RuntimeError, *NPY_HEADER_ERRORS)
    try:
        with zipfile.ZipFile(path) as archive:
            members = [info for info in archive.infolist() if info.filename.endswith(".npy")]
            if len(members) > MAX_NPZ_MEMBERS:
                raise error(f"{path}: holds {len(members)} arrays, more than {MAX_NPZ_MEMBERS}")
            for info in members:
                key = info.filename[: -len(".npy")]
                with archive.open(info) as member:
                    arrays[key] = _read_npz_member(
                        member, path, key, key in text_keys, error, max_member_bytes
                    )
    except unreadable as e:
        if isinstance(e, DataFileError):
            raise
        raise error(f"{path}: not a readable .npz file ({type(e).__name__}: {e})") from None
    return arrays


def _read_npz_member(
    member: BinaryIO, path: Path, key: str, text: bool, error: type[DataFileError], max_bytes: int
) -> np.ndarray:
    """One member's array: header checked (dtype, size) first, then exactly its bytes inflated."""
    shape, fortran, dtype = _npy_header(member)
    if not (text and dtype.kind == "U"):
        check_real(np.empty(0, dtype), str(path), key, error)
    size = math.prod(shape) * dtype.itemsize
    if size > max_bytes:
        raise error(f"{path}: {key!r}: the header claims {shape} {dtype} ({size} bytes), more than the "
                    f"{max_bytes} bytes an array may inflate to")  # fmt: skip
    buffer = bytearray(size)
    view, got = memoryview(buffer), 0
    while got < size:
        n = member.readinto(view[got:])
        if not n:
            raise error(f"{path}: {key!r}: truncated (the header says {size} bytes, {got} follow)")
        got += n
    if member.read(1):
        raise error(f"{path}: {key!r}: more data than its header says ({shape} {dtype})")
    return np.frombuffer(buffer, dtype).reshape(shape, order="F" if fortran else "C")
