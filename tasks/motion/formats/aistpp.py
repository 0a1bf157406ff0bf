"""AIST++ motions: reading the annotation pickles, splits, music pairing and 5 s windows.

Facts (google/aistplusplus_api ``aist_plusplus/loader.py``, the [AIST++] site): ``motions/<name>.pkl``
holds ``smpl_poses`` (N, 72) or (N, 24, 3) axis-angle, ``smpl_trans`` (N, 3) and ``smpl_scaling`` (1,) at
exactly 60 fps, y-up; the root position in metres is ``smpl_trans / smpl_scaling``. The pickles are read with
:func:`~skeleton_mamba.tasks.motion.io.safe_pickle.safe_load_pickle` (numpy arrays and plain values only).

Splits ship as package data (``aistpp_splits/*.txt``, copied from Stanford-TML/EDGE
``data/splits``): ``crossmodal_train`` (980 names), ``crossmodal_test`` (20) and ``ignore_list`` (45
sequences with poorly reconstructed 3D). No crossmodal *val* list is available to this project
(EDGE ships none; the AIST++ val split has 20 sequences sharing the test music ids), so
``load_split("val")`` raises and says so.

Names look like ``gBR_sBM_cAll_d04_mBR0_ch01``: genre, situation, camera, dancer, music id,
choreography; the music file of a sequence is ``<music id>.wav`` (e.g. ``mBR0.wav``).
"""

from __future__ import annotations

import re
from importlib.resources import files
from os import PathLike
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.tasks.motion.body.resample import resample_smpl
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, MotionFileError
from skeleton_mamba.tasks.motion.formats.registry import MOTION_FORMATS, FileMotion, ReadRequest
from skeleton_mamba.tasks.motion.io.safe_pickle import safe_load_pickle
from skeleton_mamba.tasks.motion.io.value_checks import check_real

__all__ = [
    "AISTPP_FPS",
    "SPLIT_NAMES",
    "load_aistpp_motion",
    "load_split",
    "ignore_list",
    "split_sequences",
    "music_id",
    "music_path",
    "window_starts",
    "motion_windows",
]

AISTPP_FPS = 60.0
SPLIT_NAMES = {"train": "crossmodal_train", "test": "crossmodal_test", "ignore": "ignore_list"}
_NAME = re.compile(r"^g[A-Z]{2}_s[A-Z]{2}_c(?:All|\d{2})_d\d{2}_(m[A-Z]{2}\d)_ch\d{2}$")


def load_aistpp_motion(path: str | PathLike[str]) -> MotionData:
    """Read one AIST++ ``motions/*.pkl`` file as a 60 fps SMPL-24 :class:`MotionData`.

    Raises:
        UnsafePickleError: the pickle names anything beyond numpy arrays and plain values, or claims
            sizes beyond the unpickler's bounds.
        MotionFileError: keys, shapes or dtypes are wrong (complex, datetime, object arrays are refused,
            not cast), or values are implausible (the message names the file and the key).

    Examples:
        An AIST++ annotation pickle: SMPL poses (T, 72), root translation (T, 3) in centimetres, the scale.

        >>> import pickle, tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> data = {"smpl_poses": np.zeros((3, 72)), "smpl_trans": np.zeros((3, 3))}
        >>> data["smpl_scaling"] = np.array([93.0])
        >>> path = Path(tempfile.mkdtemp()) / "gBR_sBM_cAll_d04_mBR0_ch01.pkl"
        >>> _ = path.write_bytes(pickle.dumps(data))
        >>> motion = load_aistpp_motion(path)
        >>> motion.fps, motion.skeleton, motion.poses.shape, motion.scaling
        (60.0, 'smpl24', (3, 24, 3), 93.0)
    """
    path = Path(path)
    data = safe_load_pickle(path)
    if not isinstance(data, dict):
        raise MotionFileError(f"{path}: expected a dict of arrays, got {type(data).__name__}")
    missing = [k for k in ("smpl_poses", "smpl_trans", "smpl_scaling") if k not in data]
    if missing:
        raise MotionFileError(f"{path}: missing keys {missing} (found {sorted(map(str, data))})")
    for key in ("smpl_poses", "smpl_trans", "smpl_scaling"):
        try:
            value = np.asarray(data[key])  # lists of numbers become arrays; ragged or mixed ones objects
        except (TypeError, ValueError) as e:
            raise MotionFileError(f"{path}: {key!r} must be a numeric array ({e})") from None
        check_real(value, str(path), key, MotionFileError)  # complex or datetime would be cast silently
    try:
        with np.errstate(over="ignore"):  # beyond float32 becomes Inf, refused by validate()
            poses = np.asarray(data["smpl_poses"], dtype=np.float32)  # (N, 72) is reshaped by MotionData
            trans = np.asarray(data["smpl_trans"], dtype=np.float32)
        scaling = np.asarray(data["smpl_scaling"], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError, OverflowError) as e:
        raise MotionFileError(f"{path}: smpl_poses, smpl_trans, smpl_scaling must be numeric ({e})") from None
    if scaling.size != 1:
        raise MotionFileError(f"{path}: smpl_scaling must hold one value, got shape {scaling.shape}")
    motion = MotionData(AISTPP_FPS, "smpl24", poses=poses, trans=trans, scaling=float(scaling[0]))
    return motion.validate(str(path))


def load_split(split: str) -> list[str]:
    """Sequence names of a split: ``"train"``, ``"test"`` or ``"ignore"`` (or the file stems).

    Examples:
        >>> test = load_split("test")
        >>> len(test), all(name.startswith("g") for name in test)
        (20, True)
    """
    stem = SPLIT_NAMES.get(split, split)
    if stem in ("val", "crossmodal_val"):
        raise FileNotFoundError(
            "no AIST++ crossmodal val list ships with skeleton_mamba (Stanford-TML/EDGE provides only "
            "train, test and the ignore list); pass your own name list or validate on the test split"
        )
    resource = files("skeleton_mamba.tasks.motion.formats") / "aistpp_splits" / f"{stem}.txt"
    if not resource.is_file():
        raise FileNotFoundError(f"unknown AIST++ split {split!r}; known: {sorted(SPLIT_NAMES)}")
    lines = resource.read_text(encoding="utf-8").splitlines()
    return [line.strip() for line in lines if line.strip() and not line.startswith("#")]


def ignore_list() -> set[str]:
    """The 45 AIST++ sequences with poorly reconstructed 3D (excluded everywhere)."""
    return set(load_split("ignore"))


def split_sequences(split: str, exclude_ignored: bool = True) -> list[str]:
    """:func:`load_split` minus the ignore list (by default), order kept."""
    names = load_split(split)
    if not exclude_ignored:
        return names
    ignored = ignore_list()
    return [n for n in names if n not in ignored]


def music_id(name: str) -> str:
    """The music id of a sequence name: ``gBR_sBM_cAll_d04_mBR0_ch01`` -> ``mBR0``."""
    stem = Path(name).stem
    match = _NAME.match(stem)
    if match is None:
        raise ValueError(f"{name!r} is not an AIST++ sequence name like 'gBR_sBM_cAll_d04_mBR0_ch01'")
    return match.group(1)


def music_path(music_dir: str | PathLike[str], name: str, suffix: str = ".wav") -> Path:
    """The music file paired with a sequence: ``<music_dir>/<music id><suffix>``."""
    return Path(music_dir) / f"{music_id(name)}{suffix}"


def window_starts(num_frames: int, window: int, stride: int) -> list[int]:
    """Start frames of all full windows of ``window`` frames taken every ``stride`` frames."""
    if window <= 0 or stride <= 0:
        raise ValueError(f"window and stride must be positive, got window={window}, stride={stride}")
    return list(range(0, num_frames - window + 1, stride))


def motion_windows(
    motion: MotionData,
    fps: float = 30.0,
    window_seconds: float = 5.0,
    stride_seconds: float = 0.5,
) -> list[MotionData]:
    """Resample an SMPL motion to ``fps`` and cut it into full windows.

    Rotations are slerped and translation interpolated (:func:`resample_smpl`); from 60 to 30 fps this
    is every second frame. Each window has ``round(window_seconds * fps)`` frames (150 for 5 s at
    30 fps) and windows start every ``round(stride_seconds * fps)`` frames (EDGE: 0.5 s).

    Returns:
        Windows as :class:`MotionData` at ``fps`` (empty when the motion is shorter than a window).
    """
    if motion.poses is None or motion.trans is None:
        raise ValueError("motion_windows needs SMPL parameters (poses and trans)")
    window = round(window_seconds * fps)
    stride = round(stride_seconds * fps)
    poses, trans = resample_smpl(
        torch.from_numpy(np.asarray(motion.poses, dtype=np.float64)),
        torch.from_numpy(np.asarray(motion.trans, dtype=np.float64)),
        motion.fps,
        fps,
    )
    poses_np, trans_np = poses.numpy().astype(np.float32), trans.numpy().astype(np.float32)
    return [
        MotionData(
            fps=fps,
            skeleton="smpl24",
            poses=poses_np[s : s + window],
            trans=trans_np[s : s + window],
            scaling=motion.scaling,
        )
        for s in window_starts(len(poses_np), window, stride)
    ]


@MOTION_FORMATS.register(".pkl")
def read_aistpp_motion(path: Path, request: ReadRequest) -> FileMotion:
    """an AIST++ motion ``.pkl`` (60 fps SMPL, read with the restricted unpickler)"""
    return FileMotion(load_aistpp_motion(path))
