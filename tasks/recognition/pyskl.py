"""PYSKL skeleton annotation files (``kennymckormick/pyskl tools/data/README.md``).

A pickle holding ``{"split": {name: [frame_dir, ...]}, "annotations": [annotation, ...]}``; each
annotation has ``frame_dir`` (str), ``label`` (0-based int), ``keypoint`` (M, T, V, C) with C = 3 for 3D
or 2 for 2D, ``total_frames`` (= T) and, for 2D data, ``keypoint_score`` (M, T, V); other keys
(``img_shape``, ``original_shape``, ...) are kept as they are. Files from outside are read with the
restricted unpickler of :mod:`skeleton_mamba.tasks.motion.io.safe_pickle`, never plain ``pickle.load``.
"""

from __future__ import annotations

import pickle
from collections.abc import Iterator, Sequence
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.tasks.motion.io.safe_pickle import safe_load_pickle
from skeleton_mamba.tasks.motion.io.value_checks import check_finite

__all__ = [
    "AnnotationFileError",
    "check_structure",
    "iter_validated",
    "load_annotations",
    "save_annotations",
    "validate_annotations",
    "validate_split",
]


class AnnotationFileError(DataFileError):
    """A PYSKL annotation file does not have the documented structure (the message names the file)."""


def _int(value: Any) -> int | None:
    """``value`` as a Python int when it is an integer (numpy integers included), else None."""
    if isinstance(value, bool | np.bool_):
        return None
    if isinstance(value, int | np.integer):
        return int(value)
    return None


def _finite_float32(array: np.ndarray, where: str, what: str) -> np.ndarray:
    """``array`` as float32, refusing NaN, Inf and values beyond the float32 range."""
    with np.errstate(over="ignore"):  # an overflow becomes Inf, refused by check_finite
        out = np.asarray(array, dtype=np.float32)
    return check_finite(out, where, what, ("body", "frame", "joint"), AnnotationFileError)


def _validate_annotation(anno: Any, index: int, source: str) -> dict:
    where = f"{source}: annotation {index}"
    if not isinstance(anno, dict):
        raise AnnotationFileError(f"{where}: expected a dict, got {type(anno).__name__}")
    frame_dir = anno.get("frame_dir")
    if not isinstance(frame_dir, str) or not frame_dir:
        raise AnnotationFileError(f"{where}: 'frame_dir' must be a non-empty string, got {frame_dir!r}")
    where = f"{source}: annotation {index} ({frame_dir})"
    if "keypoint" not in anno:
        raise AnnotationFileError(
            f"{where}: no 'keypoint' array (annotations that keep keypoints "
            "in separate kpfiles, like PYSKL's K400 file, are unsupported)"
        )
    label = _int(anno.get("label"))
    if label is None or label < 0:
        raise AnnotationFileError(f"{where}: 'label' must be a 0-based integer, got {anno.get('label')!r}")
    keypoint = anno["keypoint"]
    if not isinstance(keypoint, np.ndarray) or keypoint.ndim != 4 or keypoint.shape[-1] not in (2, 3):
        shape = getattr(keypoint, "shape", type(keypoint).__name__)
        raise AnnotationFileError(f"{where}: 'keypoint' must be an array (M, T, V, C=2|3), got {shape}")
    if not np.issubdtype(keypoint.dtype, np.number):
        raise AnnotationFileError(f"{where}: 'keypoint' must be numeric, got dtype {keypoint.dtype}")
    total_frames = _int(anno.get("total_frames"))
    if total_frames is None or total_frames != keypoint.shape[1]:
        raise AnnotationFileError(f"{where}: 'total_frames' ({anno.get('total_frames')!r}) must be an "
                                  f"integer equal to the T axis of 'keypoint' {keypoint.shape}")  # fmt: skip
    out = dict(anno)
    out.update(label=label, total_frames=total_frames, keypoint=_finite_float32(keypoint, where, "keypoint"))
    if keypoint.shape[-1] == 2 or "keypoint_score" in anno:
        score = anno.get("keypoint_score")
        if not isinstance(score, np.ndarray) or score.shape != keypoint.shape[:3]:
            shape = getattr(score, "shape", None if score is None else type(score).__name__)
            raise AnnotationFileError(f"{where}: 2D keypoints need 'keypoint_score' of shape "
                                      f"{keypoint.shape[:3]} (M, T, V), got {shape}")  # fmt: skip
        if not np.issubdtype(score.dtype, np.number):
            raise AnnotationFileError(f"{where}: 'keypoint_score' must be numeric, got dtype {score.dtype}")
        out["keypoint_score"] = _finite_float32(score, where, "keypoint_score")
    return out


def validate_annotations(data: Any, source: str = "<annotations>") -> dict:
    """Check the PYSKL structure and return a normalized copy.

    Args:
        data: the unpickled object.
        source: how to name it in error messages (the file path).

    Returns:
        ``{"split": {name: [frame_dir]}, "annotations": [...]}`` with ``label`` / ``total_frames`` as
        Python ints and ``keypoint`` / ``keypoint_score`` as float32 arrays; other top-level and
        per-annotation keys are kept.

    Raises:
        AnnotationFileError: a missing or ill-typed field, a duplicate ``frame_dir``, or a split naming a
            ``frame_dir`` that has no annotation.
    """
    check_structure(data, source)
    seen: set[str] = set()
    annos = list(iter_validated(data["annotations"], source, seen))
    out = dict(data)
    out.update(split=validate_split(data["split"], seen, source), annotations=annos)
    return out


def check_structure(data: Any, source: str) -> None:
    """Refuse an object that is not a dict with ``split`` and an ``annotations`` list."""
    if not isinstance(data, dict) or "split" not in data or "annotations" not in data:
        keys = sorted(data) if isinstance(data, dict) else type(data).__name__
        raise AnnotationFileError(f"{source}: expected a dict with 'split' and 'annotations', got {keys}")
    annotations = data["annotations"]
    if not isinstance(annotations, list | tuple):
        raise AnnotationFileError(f"{source}: 'annotations' must be a list, got {type(annotations).__name__}")


def iter_validated(annotations: Sequence[Any], source: str, seen: set[str]) -> Iterator[dict]:
    """Each annotation checked and normalized (:func:`validate_annotations`), one at a time; ``seen``
    collects the ``frame_dir`` names, a repeated one refused."""
    for index, anno in enumerate(annotations):
        anno = _validate_annotation(anno, index, source)
        if anno["frame_dir"] in seen:
            raise AnnotationFileError(f"{source}: frame_dir {anno['frame_dir']!r} appears twice")
        seen.add(anno["frame_dir"])
        yield anno


def validate_split(split: Any, seen: set[str], source: str) -> dict[str, list[str]]:
    """The ``split`` dict checked: names mapping to lists of ``frame_dir`` that are all in ``seen``."""
    if not isinstance(split, dict):
        raise AnnotationFileError(f"{source}: 'split' must be a dict name -> list of frame_dir, "
                                  f"got {type(split).__name__}")  # fmt: skip
    clean_split: dict[str, list[str]] = {}
    for name, members in split.items():
        if not isinstance(name, str) or not isinstance(members, list | tuple):
            raise AnnotationFileError(f"{source}: split {name!r} must map a name to a list of frame_dir")
        if not all(isinstance(m, str) for m in members):
            raise AnnotationFileError(f"{source}: split {name!r} must list frame_dir strings")
        unknown = [m for m in members if m not in seen]
        if unknown:
            raise AnnotationFileError(f"{source}: split {name!r} names {len(unknown)} frame_dir without an "
                                      f"annotation, e.g. {unknown[:3]}")  # fmt: skip
        clean_split[name] = list(members)
    return clean_split


def load_annotations(path: str | PathLike[str]) -> dict:
    """Load and validate a PYSKL annotation pickle (2D or 3D) with the restricted unpickler.

    Raises:
        FileNotFoundError: no such file.
        skeleton_mamba.tasks.motion.io.safe_pickle.UnsafePickleError: the pickle names a global other than
            numpy arrays and plain Python values (nothing in it is run), or is not a pickle.
        AnnotationFileError: the structure is not PYSKL's (see :func:`validate_annotations`).
    """
    return validate_annotations(safe_load_pickle(path), str(path))


KEYPOINT_DTYPES = ("float32", "float16")


def _cast(anno: dict, dtype: str, source: str) -> dict:
    """``keypoint`` / ``keypoint_score`` of one annotation in ``dtype``; overflowing values are refused."""
    out = dict(anno)
    for key in ("keypoint", "keypoint_score"):
        if key in out:
            with np.errstate(over="ignore"):  # overflow is reported below, naming the sample
                cast = out[key].astype(dtype)
            if not np.isfinite(cast).all():
                raise AnnotationFileError(f"{source}: {anno['frame_dir']}: {key} exceeds the {dtype} range")
            out[key] = cast
    return out


def save_annotations(data: dict, path: str | PathLike[str], keypoint_dtype: str = "float32") -> Path:
    """Validate ``data`` and write it as a standard pickle, atomically (temp file + ``os.replace``).

    The pickle uses protocol 4 and holds only dicts, lists, strings, ints and numpy arrays, so PYSKL,
    mmaction2 and :func:`load_annotations` all read it. ``keypoint_dtype`` stores ``keypoint`` and
    ``keypoint_score`` as float32 (default, lossless for the parsed values) or float16 (PYSKL's own files:
    tools/data/ntu_preproc.py, custom_2d_skeleton.py; half the size, about 3 significant digits).

    Raises:
        AnnotationFileError: the structure is wrong, or a value does not fit in ``keypoint_dtype``.

    Returns:
        The written path.
    """
    path = Path(path)
    data = validate_annotations(data, str(path))
    if keypoint_dtype not in KEYPOINT_DTYPES:
        raise ValueError(f"keypoint_dtype must be one of {KEYPOINT_DTYPES}, got {keypoint_dtype!r}")
    if keypoint_dtype != "float32":
        data["annotations"] = [_cast(a, keypoint_dtype, str(path)) for a in data["annotations"]]
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path, "wb") as f:
        pickle.dump(data, f, protocol=4)
    return path
