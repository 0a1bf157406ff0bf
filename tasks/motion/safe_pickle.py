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
"""

from __future__ import annotations

import codecs
import collections
import io
import pickle
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from skeleton_mamba.tasks.motion.errors import SkeletonMambaError

__all__ = [
    "UnsafePickleError",
    "safe_load_pickle",
    "safe_loads_pickle",
    "ALLOWED_GLOBALS",
    "ChumpyArray",
    "SparseMatrix",
]


class UnsafePickleError(SkeletonMambaError, ValueError):
    """A pickle names a global outside the allow-list (or is not a readable pickle)."""


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
    import numpy._core.multiarray as multiarray  # lazy: numpy 2 only
    import numpy._core.numeric as numeric  # lazy: numpy 2 only

    return {"multiarray": multiarray, "numeric": numeric}[module].__dict__[name]


def _build_allowed() -> dict[tuple[str, str], Any]:
    allowed: dict[tuple[str, str], Any] = {
        ("numpy", "ndarray"): np.ndarray,
        ("numpy", "dtype"): np.dtype,
        ("_codecs", "encode"): codecs.encode,
        ("collections", "OrderedDict"): collections.OrderedDict,
    }
    for core in ("numpy.core", "numpy._core"):
        allowed[(f"{core}.multiarray", "_reconstruct")] = _numpy_core_attr("multiarray", "_reconstruct")
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
            allowed[(module, t.__name__)] = t
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


class _RestrictedUnpickler(pickle.Unpickler):
    def __init__(self, file: Any, source: str, encoding: str = "ASCII") -> None:
        super().__init__(file, encoding=encoding)
        self._source = source

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


def _load(file: Any, source: str, encoding: str = "ASCII") -> Any:
    try:
        return _RestrictedUnpickler(file, source, encoding).load()
    except UnsafePickleError:
        raise
    except (
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
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such pickle file")
    with path.open("rb") as f:
        return _load(f, str(path), encoding)


def safe_loads_pickle(data: bytes, source: str = "<bytes>", encoding: str = "ASCII") -> Any:
    """:func:`safe_load_pickle` for an in-memory pickle; ``source`` names it in error messages."""

    return _load(io.BytesIO(data), source, encoding)
