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
  and ``collections.OrderedDict``.
"""

from __future__ import annotations

import codecs
import collections
import pickle
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["UnsafePickleError", "safe_load_pickle", "safe_loads_pickle", "ALLOWED_GLOBALS"]


class UnsafePickleError(ValueError):
    """A pickle names a global outside the allow-list (or is not a readable pickle)."""


def _numpy_core_attr(module: str, name: str) -> Any:
    # numpy 2 keeps its internals in numpy._core; numpy.core is a deprecated alias. Resolve the
    # object directly so that reading a numpy-1 pickle neither imports numpy.core nor warns.
    import numpy._core.multiarray as multiarray
    import numpy._core.numeric as numeric

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
    return allowed


ALLOWED_GLOBALS: dict[tuple[str, str], Any] = _build_allowed()


class _RestrictedUnpickler(pickle.Unpickler):
    def __init__(self, file: Any, source: str) -> None:
        super().__init__(file)
        self._source = source

    def find_class(self, module: str, name: str) -> Any:
        try:
            return ALLOWED_GLOBALS[(module, name)]
        except KeyError:
            raise UnsafePickleError(
                f"{self._source}: refusing to unpickle global '{module}.{name}'; only numpy arrays and "
                "plain Python values are admitted (the file may try to run code)"
            ) from None

    def persistent_load(self, pid: Any) -> Any:
        raise UnsafePickleError(f"{self._source}: persistent ids are not admitted (got {pid!r})")


def _load(file: Any, source: str) -> Any:
    try:
        return _RestrictedUnpickler(file, source).load()
    except UnsafePickleError:
        raise
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, IndexError) as e:
        raise UnsafePickleError(f"{source}: not a readable data pickle ({type(e).__name__}: {e})") from e


def safe_load_pickle(path: str | PathLike[str]) -> Any:
    """Load a pickle file admitting only numpy arrays and plain Python values.

    Args:
        path: the ``.pkl`` file.

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
        return _load(f, str(path))


def safe_loads_pickle(data: bytes, source: str = "<bytes>") -> Any:
    """:func:`safe_load_pickle` for an in-memory pickle; ``source`` names it in error messages."""
    import io

    return _load(io.BytesIO(data), source)
