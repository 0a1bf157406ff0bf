"""Kinetics-skeleton clips as ST-GCN ships them (``yysijie/st-gcn OLD_README.md``, ``feeder_kinetics.py``).

One JSON per clip (``kinetics_{train,val}/<video_id>.json``)::

    {"data": [{"frame_index": 1,
               "skeleton": [{"pose": [x0, y0, ..., x17, y17], "score": [s0, ..., s17]}, ...]},
              ...],
     "label": "abseiling", "label_index": 0}

plus ``kinetics_{train,val}_label.json`` = ``{video_id: {"has_skeleton", "label", "label_index"}}``.
Coordinates are OpenPose-18 joints normalized to [0, 1] by the 340x256 frame size.

Bodies follow the ST-GCN feeder: the first ``num_person_in`` (5) people of each frame are read, then in
every frame the people are sorted by their summed joint score and the best ``num_person_out`` (2) kept
(slots are per frame, not tracked). Unlike ST-GCN's fixed 300-frame buffer indexed by ``frame_index``, the
clip keeps its true length, PYSKL style: frame ``i`` lands at ``frame_index[i] - min(frame_index)``.

Files are parsed by the project's bounded reader (:mod:`skeleton_mamba.io.bounded_read`: a regular file,
finite numbers, integers of at most :data:`MAX_INT_DIGITS` digits) with Kinetics' bounds: at most
:data:`MAX_JSON_BYTES` bytes, nested at most :data:`MAX_JSON_DEPTH` levels; label indices below
:data:`MAX_LABEL_INDEX`, and pose / score values that are JSON numbers (not strings).
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.io.bounded_read import MAX_INT_DIGITS, read_json
from skeleton_mamba.tasks.motion.io.value_checks import check_finite

__all__ = [
    "MAX_INT_DIGITS",
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_LABEL_INDEX",
    "NUM_JOINTS",
    "KineticsFileError",
    "read_kinetics_clip",
    "read_kinetics_labels",
]

NUM_JOINTS = 18  # OpenPose COCO-18
MAX_FRAMES = 100_000  # a frame_index span beyond this (~55 min at 30 fps) is refused, not allocated
MAX_JSON_BYTES = 256 << 20  # a clip is about 1 MB; the train label file of Kinetics-400 about 30 MB
MAX_JSON_DEPTH = 16  # the layout nests 5 levels (clip, data, frame, skeleton, person)
MAX_LABEL_INDEX = 100_000  # Kinetics has 400 (to 700) classes; larger indices size label arrays absurdly


class KineticsFileError(DataFileError):
    """A Kinetics-skeleton JSON file does not follow the ST-GCN layout (the message names the file)."""


def _load_json(path: Path) -> Any:
    """The clip or label file through the project's bounded JSON reader, with Kinetics' bounds."""
    bounds = {"max_bytes": MAX_JSON_BYTES, "max_depth": MAX_JSON_DEPTH}
    return read_json(path, **bounds, what="Kinetics file", error=KineticsFileError)


def _numbers(values: Any, count: int, what: str) -> np.ndarray:
    if not isinstance(values, list) or len(values) != count:
        got = len(values) if isinstance(values, list) else type(values).__name__
        raise KineticsFileError(f"{what}: expected a list of {count} numbers, got {got}")
    for k, value in enumerate(values):  # numpy would parse strings such as "0.5" as numbers
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise KineticsFileError(f"{what}: entry {k} is {type(value).__name__} {str(value)[:20]!r}, "
                                    "not a number")  # fmt: skip
    try:
        with np.errstate(over="ignore"):  # beyond float32 becomes Inf, refused below
            array = np.asarray(values, dtype=np.float32)
    except (TypeError, ValueError, OverflowError):
        raise KineticsFileError(f"{what}: expected {count} numbers, got non-numeric values") from None
    if array.shape != (count,):
        raise KineticsFileError(f"{what}: expected a flat list of {count} numbers, got shape {array.shape}")
    return check_finite(array, what, "value", ("entry",), KineticsFileError)


def read_kinetics_clip(
    path: str | PathLike[str], num_person_in: int = 5, num_person_out: int = 2
) -> tuple[np.ndarray, np.ndarray, int, str]:
    """Read one ST-GCN Kinetics-skeleton clip.

    Args:
        path: the clip's JSON file.
        num_person_in: people read per frame, in file order (ST-GCN: 5).
        num_person_out: people kept per frame after sorting by summed score (ST-GCN: 2).

    Returns:
        ``(keypoint, score, label, label_name)``: keypoint (M, T, 18, 2) float32 (x, y in [0, 1] as
        stored), score (M, T, 18) float32, the 0-based ``label_index`` and the ``label`` string.
        M = min(``num_person_out``, most people in any frame), so a clip without any person has M = 0;
        T spans the clip's frame indices.

    Raises:
        FileNotFoundError: no such file.
        KineticsFileError: malformed JSON or layout (message names the file and the frame).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such Kinetics-skeleton clip")
    clip = _load_json(path)
    if not isinstance(clip, dict) or not isinstance(clip.get("data"), list):
        raise KineticsFileError(f"{path}: expected an object with a 'data' list of frames")
    label, label_name = clip.get("label_index"), clip.get("label")
    if isinstance(label, bool) or not isinstance(label, int) or not 0 <= label < MAX_LABEL_INDEX:
        raise KineticsFileError(f"{path}: 'label_index' must be a 0-based integer below {MAX_LABEL_INDEX}, "
                                f"got {str(label)[:20]}")  # fmt: skip
    if not isinstance(label_name, str):
        raise KineticsFileError(f"{path}: 'label' must be the class name string, got {label_name!r}")

    frames: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    for i, frame in enumerate(clip["data"]):
        where = f"{path}: data[{i}]"
        index = frame.get("frame_index") if isinstance(frame, dict) else None
        if isinstance(index, bool) or not isinstance(index, int) or index < 0:
            raise KineticsFileError(f"{where}: expected an object with an integer 'frame_index' >= 0")
        if index in frames:
            raise KineticsFileError(f"{where}: frame_index {index} appears twice")
        people = frame.get("skeleton")
        if not isinstance(people, list):
            raise KineticsFileError(f"{where}: 'skeleton' must be a list of people")
        frames[index] = []
        for m, person in enumerate(people[:num_person_in]):
            if not isinstance(person, dict):
                raise KineticsFileError(f"{where}.skeleton[{m}]: expected an object with 'pose' and 'score'")
            pose = _numbers(person.get("pose"), 2 * NUM_JOINTS, f"{where}.skeleton[{m}].pose")
            score = _numbers(person.get("score"), NUM_JOINTS, f"{where}.skeleton[{m}].score")
            frames[index].append((pose.reshape(NUM_JOINTS, 2), score))

    if not frames:
        empty = np.zeros((0, 0, NUM_JOINTS), np.float32)
        return empty[..., None].repeat(2, -1), empty, label, label_name
    first, last = min(frames), max(frames)
    if last - first >= MAX_FRAMES:
        raise KineticsFileError(f"{path}: frame_index runs from {first} to {last}, more than {MAX_FRAMES} "
                                "frames (a Kinetics clip has about 300)")  # fmt: skip
    num_people = min(num_person_out, max(len(p) for p in frames.values()))
    keypoint = np.zeros((num_people, last - first + 1, NUM_JOINTS, 2), np.float32)
    score = np.zeros((num_people, last - first + 1, NUM_JOINTS), np.float32)
    for index, people in frames.items():
        # ST-GCN: per frame, sort people by summed joint score (descending; stable for ties)
        order = sorted(range(len(people)), key=lambda m: -float(people[m][1].sum()))[:num_people]
        for slot, m in enumerate(order):
            keypoint[slot, index - first], score[slot, index - first] = people[m]
    return keypoint, score, label, label_name


def read_kinetics_labels(path: str | PathLike[str]) -> dict[str, dict]:
    """Read ``kinetics_{train,val}_label.json``: ``{video_id: {"has_skeleton", "label", "label_index"}}``.

    Raises:
        KineticsFileError: the file is not a JSON object of such entries.
    """
    path = Path(path)
    labels = _load_json(path)
    if not isinstance(labels, dict):
        raise KineticsFileError(f"{path}: expected an object video_id -> {{has_skeleton, label_index}}")
    for video_id, entry in labels.items():
        if not isinstance(entry, dict) or not {"has_skeleton", "label_index"} <= entry.keys():
            raise KineticsFileError(f"{path}: entry {video_id!r} needs 'has_skeleton' and 'label_index'")
        label = entry["label_index"]
        if isinstance(label, bool) or not isinstance(label, int) or not 0 <= label < MAX_LABEL_INDEX:
            raise KineticsFileError(f"{path}: entry {str(video_id)[:40]!r}: 'label_index' must be a 0-based "
                                    f"integer below {MAX_LABEL_INDEX}, got {repr(label)[:20]}")  # fmt: skip
    return labels
