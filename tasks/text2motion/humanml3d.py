"""HumanML3D files: motions, captions, split lists and statistics (``EricGuo5513/HumanML3D``).

Folder layout (as the dataset's scripts write it)::

    ROOT/new_joint_vecs/XXXXXX.npy   (T, 263) float32 features, 20 fps
    ROOT/texts/XXXXXX.txt            one caption a line: ``caption#tokens#start#end``
    ROOT/Mean.npy, ROOT/Std.npy      (263,) statistics
    ROOT/train.txt, val.txt, test.txt, train_val.txt, all.txt   one id a line

Ids ``MXXXXXX`` are the left/right mirrors of ``XXXXXX``; the dataset stores them as their own files
(mirrored motion and captions with left/right swapped), so they are read like any other id.

Clip selection follows ``Text2MotionDatasetV2`` (``EricGuo5513/text-to-motion data/dataset.py``):
motions shorter than 40 frames or of 200 frames or more are dropped; a caption with ``start``/``end``
(seconds) other than ``0.0#0.0`` describes the sub-clip of frames ``[floor(start*20), floor(end*20))``,
which becomes its own entry under the same length rule; NaN times read as 0. Training crops pick a
length that is a multiple of ``unit_length`` (4), at most ``max_motion_length`` (196).
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np

from skeleton_mamba.errors import DataFileError, DatasetNotFoundError
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FPS, NonFiniteFeaturesError, read_features

__all__ = [
    "Caption",
    "MotionClip",
    "MIN_MOTION_LENGTH",
    "MAX_MOTION_LENGTH",
    "UNIT_LENGTH",
    "is_mirrored",
    "mirror_source",
    "read_split",
    "read_motion",
    "read_captions",
    "load_clips",
    "crop_length",
]

MIN_MOTION_LENGTH = 40
MAX_MOTION_LENGTH = 196
LENGTH_LIMIT = 200  # motions of this many frames or more are dropped
UNIT_LENGTH = 4
_ID = re.compile(r"^M?\d{6}$")


@dataclass(frozen=True)
class Caption:
    """One caption line.

    Attributes:
        text: the sentence.
        tokens: spaCy ``word/POS`` tokens.
        start: start in seconds (0.0 with ``end`` 0.0 = whole clip).
        end: end in seconds.
    """

    text: str
    tokens: tuple[str, ...]
    start: float
    end: float

    @property
    def whole_clip(self) -> bool:
        return self.start == 0.0 and self.end == 0.0


@dataclass
class MotionClip:
    """A motion (or sub-clip) with the captions that describe it.

    Attributes:
        motion_id: dataset id (``"000001"`` or mirrored ``"M000001"``).
        features: (T, 263) float32 de-normalised features.
        captions: captions of this clip (at least one).
        start_frame: first frame of the clip in the id's full motion.
    """

    motion_id: str
    features: np.ndarray
    captions: list[Caption]
    start_frame: int = 0

    @property
    def length(self) -> int:
        return int(self.features.shape[0])


def is_mirrored(motion_id: str) -> bool:
    """Whether ``motion_id`` is a mirrored copy (``M`` prefix)."""
    return motion_id.startswith("M")


def mirror_source(motion_id: str) -> str:
    """The original id of a mirrored id (``"M000001"`` -> ``"000001"``); other ids unchanged."""
    return motion_id[1:] if is_mirrored(motion_id) else motion_id


def _require(path: Path, what: str) -> Path:
    if not path.is_file():
        raise DatasetNotFoundError(f"{path}: missing HumanML3D {what}")
    return path


def read_split(root: str | PathLike[str], split: str) -> list[str]:
    """Ids listed in ``ROOT/{split}.txt`` (blank lines ignored; each id checked against ``[M]dddddd``)."""
    path = _require(Path(root) / f"{split}.txt", f"split list {split!r}")
    ids = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        name = line.strip()
        if not name:
            continue
        if not _ID.match(name):
            raise DataFileError(f"{path}:{number}: malformed HumanML3D id {name!r} (6 digits, optional M)")
        ids.append(name)
    return ids


def read_motion(root: str | PathLike[str], motion_id: str) -> np.ndarray:
    """``ROOT/new_joint_vecs/{id}.npy`` as (T, 263) float32, checked by :func:`read_features`."""
    return read_features(_require(Path(root) / "new_joint_vecs" / f"{motion_id}.npy", "motion"))


def _seconds(value: str) -> float:
    number = float(value)
    return 0.0 if math.isnan(number) else number


def read_captions(root: str | PathLike[str], motion_id: str) -> list[Caption]:
    """Captions of ``ROOT/texts/{id}.txt`` (``caption#tokens#start#end`` per line)."""
    path = _require(Path(root) / "texts" / f"{motion_id}.txt", "caption file")
    captions = []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if not line.strip():
            continue
        fields = line.strip().split("#")
        if len(fields) != 4:
            raise DataFileError(f"{path}:{number}: want 'caption#tokens#start#end', got {len(fields)} fields")
        text, tokens, start, end = fields
        try:
            start_s, end_s = _seconds(start), _seconds(end)
        except ValueError as error:
            raise DataFileError(f"{path}:{number}: start/end are not numbers: {start!r}, {end!r}") from error
        captions.append(Caption(text.strip(), tuple(tokens.split()), start_s, end_s))
    if not captions:
        raise DataFileError(f"{path}: no captions")
    return captions


def _keep(length: int, min_length: int) -> bool:
    return min_length <= length < LENGTH_LIMIT


def load_clips(
    root: str | PathLike[str],
    split: str,
    min_length: int = MIN_MOTION_LENGTH,
    limit: int | None = None,
) -> list[MotionClip]:
    """Clips of a split, as ``Text2MotionDatasetV2`` builds them.

    Args:
        root: dataset folder.
        split: split list name (``train``, ``val``, ``test``, ...).
        min_length: shortest kept clip in frames (40; KIT-ML 24).
        limit: read at most this many ids (quick runs).

    Returns:
        One clip per id with its whole-clip captions, plus one clip per captioned sub-clip. Motions
        with NaN / Inf features (:class:`NonFiniteFeaturesError`) are left out with a warning that
        counts and names them.
    """
    clips = []
    excluded = []
    ids = read_split(root, split)
    for motion_id in ids[:limit] if limit is not None else ids:
        try:
            features = read_motion(root, motion_id)
        except NonFiniteFeaturesError:
            excluded.append(motion_id)
            continue
        if not _keep(len(features), min_length):
            continue
        whole = []
        for caption in read_captions(root, motion_id):
            if caption.whole_clip:
                whole.append(caption)
                continue
            first, last = int(math.floor(caption.start * FPS)), int(math.floor(caption.end * FPS))
            part = features[first:last]
            if _keep(len(part), min_length):
                clips.append(MotionClip(motion_id, part, [caption], start_frame=first))
        if whole:
            clips.append(MotionClip(motion_id, features, whole))
    if excluded:
        names = ", ".join(excluded[:10]) + (" ..." if len(excluded) > 10 else "")
        message = f"HumanML3D {split}: left out {len(excluded)} motions with NaN or Inf features: {names}"
        warnings.warn(message, stacklevel=2)
    return clips


def crop_length(length: int, rng: np.random.Generator, unit_length: int = UNIT_LENGTH) -> int:
    """Training crop length: a multiple of ``unit_length`` at most ``min(length, 196)``.

    With probability 1/3 one more unit is removed (``Text2MotionDatasetV2``'s "double" coin, used when
    ``unit_length < 10``).
    """
    length = min(length, MAX_MOTION_LENGTH)
    units = length // unit_length
    if unit_length < 10 and units > 1 and rng.integers(3) == 2:
        units -= 1
    return units * unit_length
