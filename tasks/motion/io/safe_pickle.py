"""Restricted unpickling for pickles that come from outside (AIST++ motions, PYSKL annotations).

A plain ``pickle.load`` runs whatever callable the file names (``os.system`` through ``__reduce__``,
for example). :func:`safe_load_pickle` admits only what a data pickle needs: numpy array, dtype and
scalar reconstruction, and builtins containers and scalars. Any other global makes it raise
:class:`UnsafePickleError` naming the file and the refused global, before that global is resolved
or called, so nothing from the file runs.

Admitted globals (the module names that numpy 1.x and 2.x write, and Python 2's ``__builtin__``):

- ``numpy.ndarray``, ``numpy.dtype``;
- ``numpy.core.multiarray._reconstruct`` / ``numpy._core.multiarray._reconstruct`` (protocols 0-4);
- ``numpy.core.multiarray.scalar`` / ``numpy._core.multiarray.scalar`` (numpy scalars);
- ``numpy.core.numeric._frombuffer`` / ``numpy._core.numeric._frombuffer`` (protocol 5 arrays);
- ``_codecs.encode`` (protocols 0-2 store ``bytes`` through it; it only encodes a string);
- builtins ``dict list tuple set frozenset bytearray bytes str int float complex bool slice range``
  and ``collections.OrderedDict``;
- for the official SMPL model files (Python-2 pickles, read with ``encoding="latin1"``):
  ``chumpy.ch.Ch`` becomes a :class:`ChumpyArray` that keeps only the array ``x`` of its state (chumpy
  itself is never imported), and ``scipy.sparse`` ``csc_matrix``/``csr_matrix`` (and the ``*_array``
  classes, under the old ``scipy.sparse.csc`` and the new ``scipy.sparse._csc`` module names) become a
  :class:`SparseMatrix` that keeps ``data``, ``indices``, ``indptr`` and the shape (scipy is not
  imported either). Both stand-ins only store and check arrays when the pickle restores their state;
  ``copy_reg._reconstructor`` (protocols 0-1 objects) is admitted for the stand-ins only.

Sizes are bounded before anything is allocated, so a small hostile file cannot claim gigabytes:

- the file is read by Python's own (pure-Python) unpickler through a reader that refuses any read longer
  than the bytes left in the file or than :data:`MAX_PICKLE_OBJECT_BYTES` (the C unpickler allocates a
  ``bytes`` / ``bytearray`` / frame of the claimed length before reading it);
- the admitted callables are wrapped: ``bytes(n)`` / ``bytearray(n)`` and numpy arrays (``ndarray(shape,
  dtype)``, ``_reconstruct``) are refused above :data:`MAX_PICKLE_OBJECT_BYTES`, containers built from a
  sized argument (``list(range(10**9))``) above :data:`MAX_PICKLE_ITEMS` items, object dtypes (numpy would
  allocate one Python reference per element of a claimed shape) are refused, and ``_codecs.encode`` admits
  only the latin-1 encoding that protocols 0-2 write (another codec name is refused on one line).
"""

from __future__ import annotations

import codecs
import collections
import io
import math
import os
import pickle
import struct
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from skeleton_mamba.errors import SkeletonMambaError

__all__ = [
    "UnsafePickleError",
    "safe_load_pickle",
    "safe_loads_pickle",
    "ALLOWED_GLOBALS",
    "MAX_PICKLE_ITEMS",
    "MAX_PICKLE_OBJECT_BYTES",
    "ChumpyArray",
    "SparseMatrix",
]


class UnsafePickleError(SkeletonMambaError, ValueError):
    """A pickle names a global outside the allow-list (or is not a readable pickle)."""


MAX_PICKLE_OBJECT_BYTES = 1 << 30  # one bytes object, frame or array of a data pickle: at most 1 GiB
MAX_PICKLE_ITEMS = 10_000_000  # items of one container built by a call (list(range(n)), bytes(range(n)))
_LATIN1 = {"latin1", "latin-1", "latin_1", "iso-8859-1", "iso8859-1", "iso8859_1", "l1"}


class _SizeRefused(Exception):
    """Raised by the bounded callables; turned into :class:`UnsafePickleError` naming the file."""


class ChumpyArray:
    """Stand-in for a pickled ``chumpy.ch.Ch``: keeps the array ``x`` of its state, nothing else.

    ``np.asarray(obj)`` gives the array (a Ch's value is its ``x`` for a plain, non-derived Ch).
    """

    x: np.ndarray

    def __setstate__(self, state: Any) -> None:
        if not isinstance(state, dict) or "x" not in state:
            raise pickle.UnpicklingError("a chumpy Ch without its array 'x' (only plain Ch arrays are read)")
        x = np.asarray(state["x"])
        if x.dtype.kind not in "biuf":
            raise pickle.UnpicklingError(f"a chumpy Ch whose 'x' is not numeric (dtype {x.dtype})")
        self.x = x

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        return self.x if dtype is None else self.x.astype(dtype)


class SparseMatrix:
    """Stand-in for a pickled ``scipy.sparse`` CSC or CSR matrix: compressed arrays plus shape.

    Attributes:
        format: ``"csc"`` or ``"csr"`` (from the pickled class name).
        shape: (rows, columns).
        data, indices, indptr: the compressed arrays, checked for consistency when the state is set.
    """

    format = ""

    def __setstate__(self, state: Any) -> None:
        if not isinstance(state, dict):
            raise pickle.UnpicklingError(f"a {self.format} matrix state must be a dict")
        try:
            shape = tuple(int(n) for n in state.get("_shape", state.get("shape")))
            data, indices, indptr = (np.asarray(state[k]) for k in ("data", "indices", "indptr"))
        except (KeyError, TypeError, ValueError) as err:
            raise pickle.UnpicklingError(
                f"a {self.format} matrix state needs data, indices, indptr and a shape ({err!r})"
            ) from None
        if len(shape) != 2:
            raise pickle.UnpicklingError(f"a {self.format} matrix must be 2-D, got shape {shape}")
        major = shape[1] if self.format == "csc" else shape[0]
        minor = shape[0] if self.format == "csc" else shape[1]
        ok = (
            indptr.shape == (major + 1,)
            and indices.ndim == data.ndim == 1
            and len(indices) == len(data) == int(indptr[-1])
            and indptr[0] == 0
            and bool(np.all(np.diff(indptr) >= 0))
            and (len(indices) == 0 or (indices.min() >= 0 and indices.max() < minor))
        )
        if not ok:
            raise pickle.UnpicklingError(f"inconsistent {self.format} matrix of shape {shape}")
        self.shape, self.data, self.indices, self.indptr = shape, data, indices, indptr

    def toarray(self) -> np.ndarray:
        """The dense (rows, columns) array (duplicate entries summed, as scipy does)."""
        dense = np.zeros(self.shape, dtype=np.result_type(self.data.dtype, np.float64))
        major = np.repeat(np.arange(len(self.indptr) - 1), np.diff(self.indptr))
        rows, cols = (self.indices, major) if self.format == "csc" else (major, self.indices)
        np.add.at(dense, (rows, cols), self.data)
        return dense

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        dense = self.toarray()
        return dense if dtype is None else dense.astype(dtype)


class _CSC(SparseMatrix):
    format = "csc"


class _CSR(SparseMatrix):
    format = "csr"


_STAND_INS = (ChumpyArray, _CSC, _CSR)


def _reconstructor(cls: Any, base: Any, state: Any) -> Any:
    """``copyreg._reconstructor`` restricted to the stand-ins (protocol 0-1 objects)."""
    if cls not in _STAND_INS or base is not object or state is not None:
        raise pickle.UnpicklingError("copy_reg._reconstructor is admitted for chumpy/scipy stand-ins only")
    return object.__new__(cls)


def _numpy_core_attr(module: str, name: str) -> Any:
    # numpy 2 keeps its internals in numpy._core; numpy.core is a deprecated alias. Resolve the
    # object directly so that reading a numpy-1 pickle neither imports numpy.core nor warns.
    try:
        import numpy._core.multiarray as multiarray  # lazy: numpy 2
        import numpy._core.numeric as numeric  # lazy: numpy 2
    except ImportError:  # numpy 1.x (pyproject admits >= 1.24; Blender's bpy pins 1.26): numpy.core
        import numpy.core.multiarray as multiarray  # lazy: numpy 1
        import numpy.core.numeric as numeric  # lazy: numpy 1

    return {"multiarray": multiarray, "numeric": numeric}[module].__dict__[name]


def _refuse_items(what: str, args: tuple) -> None:
    for arg in args:
        if isinstance(arg, int) and not isinstance(arg, bool) and what in ("bytes", "bytearray"):
            if arg > MAX_PICKLE_OBJECT_BYTES:
                raise _SizeRefused(f"{what}({arg}) would allocate more than {MAX_PICKLE_OBJECT_BYTES} bytes")
        elif isinstance(arg, range | str | bytes | bytearray | list | tuple | dict | set | frozenset):
            if len(arg) > MAX_PICKLE_ITEMS:
                raise _SizeRefused(f"{what}() of {len(arg)} items, more than {MAX_PICKLE_ITEMS}")


class _BoundedType:
    """An admitted builtins type whose call refuses sizes above the bounds (module docstring)."""

    def __init__(self, cls: type) -> None:
        self.cls = cls

    def __call__(self, *args: Any) -> Any:
        _refuse_items(self.cls.__name__, args)
        return self.cls(*args)

    def __repr__(self) -> str:
        return f"<bounded {self.cls.__name__}>"


def _array_bytes(shape: Any, dtype: Any) -> int:
    """Bytes of an array of ``shape`` and ``dtype`` (refused above the bound or with object elements)."""
    dtype = np.dtype(dtype)
    if dtype.hasobject:
        raise _SizeRefused(f"arrays of Python objects (dtype {dtype}) are not admitted")
    dims = (shape,) if isinstance(shape, int) else tuple(shape)
    if not all(isinstance(n, int | np.integer) and n >= 0 for n in dims):
        raise _SizeRefused(f"an array shape must be non-negative integers, got {shape!r}")
    size = math.prod(int(n) for n in dims) * dtype.itemsize
    if size > MAX_PICKLE_OBJECT_BYTES:
        raise _SizeRefused(f"an array of shape {dims} {dtype} claims {size} bytes, more than "
                           f"{MAX_PICKLE_OBJECT_BYTES}")  # fmt: skip
    return size


def _bounded_ndarray(shape: Any, dtype: Any = float, *args: Any, **kwargs: Any) -> np.ndarray:
    _array_bytes(shape, dtype)
    return np.ndarray(shape, dtype, *args, **kwargs)


def _bounded_dtype(obj: Any, *args: Any) -> np.dtype:
    dtype = np.dtype(obj, *args)
    if dtype.hasobject:
        raise _SizeRefused(f"arrays of Python objects (dtype {dtype}) are not admitted")
    if dtype.itemsize > MAX_PICKLE_OBJECT_BYTES:
        raise _SizeRefused(f"dtype {dtype} claims {dtype.itemsize} bytes per element")
    return dtype


def _bounded_reconstruct(reconstruct: Any) -> Any:
    def call(subtype: Any, shape: Any, dtype: Any) -> Any:
        if subtype is not _bounded_ndarray:
            raise _SizeRefused(f"only plain numpy arrays are admitted, got subtype {subtype!r}")
        _array_bytes(shape, np.uint8)
        return reconstruct(np.ndarray, shape, dtype)

    return call


def _latin1_encode(text: Any, encoding: str = "utf-8", *args: Any) -> bytes:
    """``_codecs.encode`` as protocols 0-2 use it (bytes stored as latin-1 text); other codecs refused."""
    if not isinstance(text, str) or str(encoding).lower() not in _LATIN1:
        raise _SizeRefused(f"_codecs.encode with the codec {str(encoding)[:40]!r} is not admitted "
                           "(protocols 0-2 store bytes as latin-1)")  # fmt: skip
    return codecs.encode(text, "latin1", *args)


def _build_allowed() -> dict[tuple[str, str], Any]:
    allowed: dict[tuple[str, str], Any] = {
        ("numpy", "ndarray"): _bounded_ndarray,
        ("numpy", "dtype"): _bounded_dtype,
        ("_codecs", "encode"): _latin1_encode,
        ("collections", "OrderedDict"): _BoundedType(collections.OrderedDict),
    }
    reconstruct = _bounded_reconstruct(_numpy_core_attr("multiarray", "_reconstruct"))
    for core in ("numpy.core", "numpy._core"):
        allowed[(f"{core}.multiarray", "_reconstruct")] = reconstruct
        allowed[(f"{core}.multiarray", "scalar")] = _numpy_core_attr("multiarray", "scalar")
        allowed[(f"{core}.numeric", "_frombuffer")] = _numpy_core_attr("numeric", "_frombuffer")
    builtin_types = (
        dict,
        list,
        tuple,
        set,
        frozenset,
        bytearray,
        bytes,
        str,
        int,
        float,
        complex,
        bool,
        slice,
        range,
    )
    for module in ("builtins", "__builtin__"):
        for t in builtin_types:
            allowed[(module, t.__name__)] = _BoundedType(t)
        allowed[(module, "object")] = object  # base class argument of copy_reg._reconstructor
    allowed[("chumpy.ch", "Ch")] = ChumpyArray
    for fmt, stand_in in (("csc", _CSC), ("csr", _CSR)):
        for module in (f"scipy.sparse.{fmt}", f"scipy.sparse._{fmt}"):
            allowed[(module, f"{fmt}_matrix")] = stand_in
            allowed[(module, f"{fmt}_array")] = stand_in
    for module in ("copy_reg", "copyreg"):
        allowed[(module, "_reconstructor")] = _reconstructor
    return allowed


ALLOWED_GLOBALS: dict[tuple[str, str], Any] = _build_allowed()


class _BoundedReader:
    """A binary stream whose reads never exceed the bytes left in it nor :data:`MAX_PICKLE_OBJECT_BYTES`."""

    def __init__(self, stream: Any, size: int, source: str) -> None:
        self._stream, self._left, self._source = stream, size, source

    def read(self, n: int = -1) -> bytes:
        if n < 0:
            n = self._left
        if n > MAX_PICKLE_OBJECT_BYTES:
            raise UnsafePickleError(
                f"{self._source}: an object claims {n} bytes, more than the {MAX_PICKLE_OBJECT_BYTES} "
                "admitted per object of a data pickle"
            )
        if n > self._left:  # checked before reading: nothing of the claimed size is allocated
            raise pickle.UnpicklingError(
                f"pickle data was truncated: an object claims {n} bytes but {self._left} are left"
            )
        data = self._stream.read(n)
        self._left -= len(data)
        if len(data) < n:
            raise pickle.UnpicklingError("pickle data was truncated")
        return data

    def readline(self) -> bytes:
        line = self._stream.readline(min(self._left, MAX_PICKLE_OBJECT_BYTES))
        self._left -= len(line)
        if not line.endswith(b"\n"):
            raise pickle.UnpicklingError("pickle data was truncated (a text line without its end)")
        return line


class _RestrictedUnpickler(pickle._Unpickler):
    # The pure-Python unpickler: it reads every counted object through ``read(n)`` (bounded above), where
    # the C one allocates the claimed length first.
    dispatch = dict(pickle._Unpickler.dispatch)

    def __init__(self, file: Any, source: str, encoding: str = "ASCII") -> None:
        super().__init__(file, encoding=encoding)
        self._source = source

    def load_bytearray8(self) -> None:
        (size,) = struct.unpack("<Q", self.read(8))
        self.append(bytearray(self.read(size)))  # read first (bounded), unlike bytearray(size) + readinto

    dispatch[pickle.BYTEARRAY8[0]] = load_bytearray8

    def find_class(self, module: str, name: str) -> Any:
        try:
            return ALLOWED_GLOBALS[(module, name)]
        except KeyError:
            raise UnsafePickleError(
                f"{self._source}: refusing to unpickle global '{module}.{name}'; only numpy arrays, "
                "plain Python values, plain chumpy Ch arrays and scipy CSC/CSR matrices are admitted "
                "(the file may try to run code)"
            ) from None

    def persistent_load(self, pid: Any) -> Any:
        raise UnsafePickleError(f"{self._source}: persistent ids are not admitted (got {pid!r})")


def _load(file: Any, size: int, source: str, encoding: str = "ASCII") -> Any:
    try:
        return _RestrictedUnpickler(_BoundedReader(file, size, source), source, encoding).load()
    except UnsafePickleError:
        raise
    except _SizeRefused as e:
        raise UnsafePickleError(f"{source}: {e} (a data pickle holds plain arrays and values)") from None
    except MemoryError:
        raise UnsafePickleError(f"{source}: out of memory while unpickling (hostile or too large)") from None
    except RecursionError:
        raise UnsafePickleError(f"{source}: nested too deeply to unpickle") from None
    except (
        LookupError,
        pickle.UnpicklingError,
        EOFError,
        ValueError,
        TypeError,
        AttributeError,
        IndexError,
        UnicodeDecodeError,
    ) as e:
        raise UnsafePickleError(f"{source}: not a readable data pickle ({type(e).__name__}: {e})") from e


def safe_load_pickle(path: str | PathLike[str], encoding: str = "ASCII") -> Any:
    """Load a pickle file admitting only numpy arrays and plain Python values.

    Args:
        path: the ``.pkl`` file.
        encoding: how Python-2 ``str`` objects are decoded (``"latin1"`` for Python-2 pickles holding
            numpy arrays, such as the official SMPL models); the default refuses non-ASCII ones.

    Returns:
        The unpickled object (dicts, lists, numpy arrays, ...).

    Raises:
        FileNotFoundError: the file does not exist.
        UnsafePickleError: the pickle names a global outside :data:`ALLOWED_GLOBALS` (nothing from the
            file is run) or is truncated / not a pickle. The message names the file.

    Examples:
        >>> import pickle, tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "data.pkl"
        >>> _ = path.write_bytes(pickle.dumps({"poses": np.zeros((2, 3)), "name": "clip"}))
        >>> data = safe_load_pickle(path)
        >>> data["poses"].shape, data["name"]
        ((2, 3), 'clip')
        >>> _ = path.write_bytes(pickle.dumps(Path("x")))  # a class outside ALLOWED_GLOBALS
        >>> safe_load_pickle(path)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        skeleton_mamba.tasks.motion.io.safe_pickle.UnsafePickleError: ...data.pkl: ...
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such pickle file")
    with path.open("rb") as f:
        return _load(f, os.fstat(f.fileno()).st_size, str(path), encoding)


def safe_loads_pickle(data: bytes, source: str = "<bytes>", encoding: str = "ASCII") -> Any:
    """:func:`safe_load_pickle` for an in-memory pickle; ``source`` names it in error messages.

    Examples:
        >>> import pickle
        >>> safe_loads_pickle(pickle.dumps({"fps": 30.0, "frames": [1, 2, 3]}))
        {'fps': 30.0, 'frames': [1, 2, 3]}
        >>> import os
        >>> safe_loads_pickle(pickle.dumps(os.system), source="payload")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        skeleton_mamba.tasks.motion.io.safe_pickle.UnsafePickleError: payload: ...
    """

    return _load(io.BytesIO(data), len(data), source, encoding)
