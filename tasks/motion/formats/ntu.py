"""Raw NTU RGB+D ``.skeleton`` files: parser, sample names and the choice of the main bodies.

File layout (``shahroudy/NTURGB-D Matlab/read_skeleton_file.m``), one value group per line, LF or CRLF::

    framecount
    per frame:  bodycount                       (may be 0)
      per body: bodyID clipedEdges handLeftConfidence handLeftState handRightConfidence
                handRightState isResticted leanX leanY trackingState          (10 values)
                jointCount                                                    (always 25)
                per joint: x y z depthX depthY colorX colorY
                           orientationW orientationX orientationY orientationZ trackingState  (12 values)

``bodyID`` is a 64-bit integer and is kept as a Python ``int`` (ST-GCN's reader casts it to float and
loses precision). x, y, z are Kinect v2 camera-space coordinates in metres.

:meth:`NTUSequence.keypoints` follows PYSKL ``tools/data/ntu_preproc.py`` (``gen_keypoint_array``): bodies
are tracked by ``bodyID`` on a timeline that skips zero-body frames; they are ranked by motion (sum of the
per-coordinate variance of all their joints), bodies seen in at most 11 frames and bodies whose frames are
mostly "wider than tall" (x-range > 0.8 y-range in at least 69.754 % of their frames) are dropped as Kinect
noise, the remaining bodies fill ``max_bodies`` slots greedily (a body joins the first slot whose occupied
interval it does not overlap), and leading/trailing all-zero frames are trimmed.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

import numpy as np

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.skeletons import get_skeleton
from skeleton_mamba.tasks.motion.formats.registry import MOTION_FORMATS, FileMotion, JointsClip, ReadRequest

__all__ = [
    "BODY_FIELDS",
    "JOINT_FIELDS",
    "NUM_JOINTS",
    "NTUBody",
    "NTUBodyFrame",
    "NTUFrame",
    "NTUSequence",
    "SkeletonFileError",
    "parse_ntu_name",
    "read_skeleton_file",
]

NUM_JOINTS = 25
BODY_FIELDS = (
    "bodyID", "clipedEdges", "handLeftConfidence", "handLeftState", "handRightConfidence",
    "handRightState", "isResticted", "leanX", "leanY", "trackingState",
)  # fmt: skip
JOINT_FIELDS = (
    "x", "y", "z", "depthX", "depthY", "colorX", "colorY",
    "orientationW", "orientationX", "orientationY", "orientationZ", "trackingState",
)  # fmt: skip

# PYSKL ntu_preproc.py denoising constants (same values as CTR-GCN get_raw_denoised_data.py).
LENGTH_THRESHOLD = 11  # a body must be seen in more than this many frames
SPREAD_WH_RATIO = 0.8  # a frame is valid when x-range <= 0.8 * y-range
SPREAD_NOISE_RATIO = 0.69754  # a body is noise when at least this fraction of its frames is invalid
ZERO_EPS = 1e-3  # frames whose summed |xyz| is below this are empty (PYSKL ``non_zero``)

_NAME_RE = re.compile(r"S(\d{3})C(\d{3})P(\d{3})R(\d{3})A(\d{3})")


class SkeletonFileError(DataFileError):
    """A ``.skeleton`` file is truncated or malformed; the message names the file and the 1-based line."""


@dataclass
class NTUBodyFrame:
    """One body as written in one frame.

    Attributes:
        body_id: the Kinect tracking id (64-bit integer).
        info: (9,) float64, the body line after ``bodyID`` (``BODY_FIELDS[1:]``).
        joints: (25, 12) float64, one row per joint with the columns of ``JOINT_FIELDS``.
    """

    body_id: int
    info: np.ndarray
    joints: np.ndarray


@dataclass
class NTUFrame:
    """One frame of the file: the bodies it lists (possibly none)."""

    bodies: list[NTUBodyFrame] = field(default_factory=list)


@dataclass
class NTUBody:
    """One tracked body (one ``bodyID``) over the sequence.

    Attributes:
        body_id: the Kinect tracking id.
        start: index of its first frame on the timeline of non-empty frames (PYSKL ``start``).
        frame_indices: 0-based indices, in the file, of the frames that list this body.
        xyz: (T_b, 25, 3) float32 camera-space joints, one row per listed frame.
        motion: sum over x, y, z of the variance of all its joints (PYSKL ``motion``).
    """

    body_id: int
    start: int
    frame_indices: list[int]
    xyz: np.ndarray
    motion: float


@dataclass
class NTUSequence:
    """A parsed ``.skeleton`` file.

    Attributes:
        path: the file it was read from.
        frames: every frame of the file, raw (``num_frames`` entries, zero-body frames included).
        bodies: the tracked bodies in order of first appearance.
    """

    path: str
    frames: list[NTUFrame]
    bodies: list[NTUBody]

    @property
    def num_frames(self) -> int:
        """The frame count of the file (zero-body frames included)."""
        return len(self.frames)

    @property
    def num_nonempty_frames(self) -> int:
        """Frames that list at least one body (the timeline PYSKL uses)."""
        return sum(1 for f in self.frames if f.bodies)

    def keypoints(self, max_bodies: int = 2) -> np.ndarray:
        """The joints of the main bodies as PYSKL ``gen_keypoint_array`` selects them.

        Args:
            max_bodies: number of body slots (PYSKL uses 2). With a single body left after denoising the
                result has one slot, as in PYSKL.

        Returns:
            (M, T, 25, 3) float32 camera-space joints, M <= ``max_bodies``; T counts non-empty frames only,
            with leading and trailing all-zero frames trimmed. (0, 0, 25, 3) when no frame has a body.
        """
        if max_bodies < 1:
            raise ValueError(f"max_bodies must be >= 1, got {max_bodies}")
        if not self.bodies:
            return np.zeros((0, 0, NUM_JOINTS, 3), np.float32)
        ranked = sorted(self.bodies, key=lambda b: -b.motion)
        if len(ranked) == 1:
            return ranked[0].xyz[None].copy()
        # PYSKL drops short bodies; if none is long enough it would fail an assertion: keep them all.
        kept = [b for b in ranked if b.xyz.shape[0] > LENGTH_THRESHOLD] or ranked
        if len(kept) == 1:
            return kept[0].xyz[None].copy()
        kept = _spread_denoise(kept)
        if len(kept) == 1:
            return kept[0].xyz[None].copy()
        return _fill_slots(kept, max_bodies)


def _spread_denoise(bodies: list[NTUBody]) -> list[NTUBody]:
    """PYSKL ``spread_denoising``: drop bodies that are mostly wider than tall, re-rank by motion.

    A body that keeps some invalid frames is ranked by the smaller of its motion and the motion of its
    valid frames. If every body is noise (PYSKL then fails an assertion), all are kept unchanged.
    """
    scored: list[tuple[float, NTUBody]] = []
    for body in bodies:
        x, y = body.xyz[..., 0], body.xyz[..., 1]
        valid = (x.max(1) - x.min(1)) <= SPREAD_WH_RATIO * (y.max(1) - y.min(1))
        if valid.all():
            scored.append((body.motion, body))
        elif 1.0 - valid.mean() < SPREAD_NOISE_RATIO:
            scored.append((min(body.motion, _motion(body.xyz[valid])), body))
    if not scored:
        return bodies
    scored.sort(key=lambda item: -item[0])
    return [body for _, body in scored]


def _fill_slots(bodies: list[NTUBody], max_bodies: int) -> np.ndarray:
    """Place ranked bodies into ``max_bodies`` slots; the first body goes to slot 0 (PYSKL rule)."""
    length = max(b.start + b.xyz.shape[0] for b in bodies)
    keypoint = np.zeros((max_bodies, length, NUM_JOINTS, 3), np.float32)
    first = bodies[0]
    spans = [(0, 0)] * max_bodies
    spans[0] = (first.start, first.start + first.xyz.shape[0])
    keypoint[0, spans[0][0] : spans[0][1]] = first.xyz
    for body in bodies[1:]:
        s, e = body.start, body.start + body.xyz.shape[0]
        for slot, (ss, se) in enumerate(spans):
            if max(ss, s) >= min(se, e):  # no overlap (an empty slot (0, 0) accepts anything)
                keypoint[slot, s:e] = body.xyz
                spans[slot] = (min(s, ss), max(e, se))
                break
    # trim leading / trailing frames where every slot is empty (PYSKL ``non_zero``)
    filled = np.abs(keypoint).sum(axis=(0, 2, 3)) >= ZERO_EPS
    if filled.any():
        first_t, last_t = np.flatnonzero(filled)[[0, -1]]
        keypoint = keypoint[:, first_t : last_t + 1]
    # PYSKL: if slot 0 has no spine joint in the first frame but another slot has, reorder the slots
    if keypoint.shape[1] and np.abs(keypoint[0, 0, 1]).sum() < ZERO_EPS:
        present = np.flatnonzero(np.abs(keypoint[:, 0, 1]).sum(-1) > ZERO_EPS)
        if present.size:
            keypoint = keypoint[::-1].copy() if max_bodies == 2 else np.roll(keypoint, -present[0], axis=0)
    return keypoint


def _motion(xyz: np.ndarray) -> float:
    """Sum over x, y, z of the variance of all joints of all frames (PYSKL ``motion``)."""
    return float(np.var(xyz.reshape(-1, 3).astype(np.float64), axis=0).sum())


def parse_ntu_name(name: str | PathLike[str]) -> dict[str, int]:
    """Decode an NTU sample name ``SsssCcccPpppRrrrAaaa`` (a path or ``.skeleton`` suffix is allowed).

    Args:
        name: e.g. ``"S001C002P003R002A013"`` or ``"/data/S001C002P003R002A013.skeleton"``.

    Returns:
        ``{"setup", "camera", "performer", "replication", "action"}``, all 1-based integers.

    Raises:
        ValueError: the name does not follow the NTU pattern.

    Examples:
        >>> parse_ntu_name("/data/S001C002P003R002A013.skeleton")
        {'setup': 1, 'camera': 2, 'performer': 3, 'replication': 2, 'action': 13}
    """
    stem = Path(name).name.split(".")[0]
    match = _NAME_RE.fullmatch(stem)
    if match is None:
        raise ValueError(f"{name!s}: not an NTU sample name (expected SsssCcccPpppRrrrAaaa)")
    keys = ("setup", "camera", "performer", "replication", "action")
    return {key: int(value) for key, value in zip(keys, match.groups())}


class _Lines:
    """Sequential access to the lines of one file, with errors that name the file and the line."""

    def __init__(self, path: str, text: str) -> None:
        self.path = path
        self.lines = text.splitlines()
        self.pos = 0  # 0-based index of the next line

    def error(self, message: str, line: int | None = None) -> SkeletonFileError:
        return SkeletonFileError(f"{self.path}: line {self.pos if line is None else line}: {message}")

    def next(self, expected: str) -> str:
        if self.pos >= len(self.lines):
            self.pos += 1
            raise self.error(f"file ends early: expected {expected}")
        line = self.lines[self.pos]
        self.pos += 1
        return line

    def count(self, expected: str) -> int:
        text = self.next(expected).strip()
        try:
            value = int(text)
        except ValueError:
            raise self.error(f"expected {expected} (an integer), got {text!r}") from None
        if value < 0:
            raise self.error(f"expected {expected} (>= 0), got {value}")
        return value

    def check_room(self, count: int, what: str) -> None:
        """Refuse a count of items (of at least one line each) that the rest of the file cannot hold."""
        left = len(self.lines) - self.pos
        if count > left:
            raise self.error(f"{count} {what} declared, but only {left} lines follow")

    def check_finite_joints(self, joints: np.ndarray, blocks: list[tuple[int, str]]) -> None:
        """Raise naming the line of the first NaN / Inf joint value (or an x, y, z beyond float32)."""
        with np.errstate(over="ignore"):
            bad = ~np.isfinite(joints)
            bad[..., :3] |= ~np.isfinite(joints[..., :3].astype(np.float32))  # kept as float32
        if bad.any():
            k, j, c = np.argwhere(bad)[0]
            first, where = blocks[k]
            value = f"{JOINT_FIELDS[c]} = {joints[k, j, c]}"
            message = f"joint {j + 1} of {where}: {value} (NaN, Inf and overflow are refused)"
            raise self.error(message, first + j + 1)

    def skip_joints(self, where: str) -> int:
        """Check that the next 25 lines are joint lines of 12 values; return the first one's index."""
        first = self.pos
        block = self.lines[first : first + NUM_JOINTS]
        width = len(JOINT_FIELDS) - 1
        if len(block) != NUM_JOINTS or any(line.count(" ") != width for line in block):
            self.parse_joints(first, where)  # raises, naming the line (or accepts other whitespace)
        self.pos = first + NUM_JOINTS
        return first

    def parse_joints(self, first: int, where: str) -> np.ndarray:
        """Strictly parse the 25 joint lines from index ``first``: (25, 12), or an error naming the line."""
        block = self.lines[first : first + NUM_JOINTS]
        for j, text in enumerate(block):
            values = text.split()
            what = f"joint {j + 1} of {where}: {len(JOINT_FIELDS)} numbers ({' '.join(JOINT_FIELDS)})"
            if len(values) != len(JOINT_FIELDS):
                raise self.error(f"expected {what}, got {len(values)} values: {text!r}", first + j + 1)
            try:
                [float(v) for v in values]
            except ValueError:
                raise self.error(f"expected {what}, got {text!r}", first + j + 1) from None
        if len(block) < NUM_JOINTS:
            line = first + len(block) + 1
            raise self.error(f"file ends early: expected joint {len(block) + 1} of {where}", line)
        return np.array([text.split() for text in block], dtype=np.float64)

    def parse_all_joints(self, blocks: list[tuple[int, str]]) -> np.ndarray:
        """Parse every checked joint block at once: (num_blocks, 25, 12) float64."""
        text = "\n".join("\n".join(self.lines[first : first + NUM_JOINTS]) for first, _ in blocks)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # numpy warns (and stops) on a token that is not a number
            try:
                values = np.fromstring(text, dtype=np.float64, sep=" ")
            except (DeprecationWarning, ValueError):
                values = np.empty(0)
        if values.size != len(blocks) * NUM_JOINTS * len(JOINT_FIELDS):
            for first, where in blocks:  # find and report the offending line
                self.parse_joints(first, where)
            raise self.error("joint values could not be parsed", blocks[0][0] + 1)  # pragma: no cover
        return values.reshape(len(blocks), NUM_JOINTS, len(JOINT_FIELDS))


def read_skeleton_file(path: str | PathLike[str]) -> NTUSequence:
    """Parse one raw NTU RGB+D ``.skeleton`` file.

    Args:
        path: the file (LF or CRLF line endings).

    Returns:
        The parsed :class:`NTUSequence` (raw frames and bodies tracked by ``bodyID``).

    Raises:
        FileNotFoundError: the file does not exist.
        SkeletonFileError: the file is truncated or malformed (message: file, 1-based line, what was
            expected), has non-blank content after the last frame, declares more frames than it has
            lines, or holds a NaN / Inf (or an x, y, z beyond float32) on a body or joint line.

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> body = "72057594037931101 0 1 1 1 1 0 0.1 0.2 2"  # bodyID and BODY_FIELDS[1:]
        >>> joint = "0.1 0.2 3.0 250 200 1000 500 1 0 0 0 2"  # JOINT_FIELDS
        >>> frame = ["1", body, "25", *[joint] * 25]  # one body of 25 joints
        >>> path = Path(tempfile.mkdtemp()) / "S001C002P003R002A013.skeleton"
        >>> _ = path.write_text("\\n".join(["2", *frame, *frame]) + "\\n")  # two frames
        >>> sequence = read_skeleton_file(path)
        >>> sequence.num_frames, len(sequence.bodies), sequence.bodies[0].xyz.shape
        (2, 1, (2, 25, 3))
        >>> sequence.bodies[0].xyz[0, 0].tolist()
        [0.10000000149011612, 0.20000000298023224, 3.0]
    """
    path_str = str(path)
    try:
        text = Path(path).read_bytes().decode("ascii")
    except UnicodeDecodeError as e:
        raise SkeletonFileError(f"{path_str}: not a text .skeleton file ({e})") from None
    lines = _Lines(path_str, text)
    num_frames = lines.count("the frame count")
    lines.check_room(num_frames, "frames")
    frames: list[NTUFrame] = []
    records: list[tuple[int, int, int, np.ndarray]] = []  # (frame, timeline index, bodyID, info)
    blocks: list[tuple[int, str]] = []  # (index of the first joint line, description) per body
    timeline = 0  # index on the timeline of non-empty frames (PYSKL skips zero-body frames)
    for f in range(num_frames):
        num_bodies = lines.count(f"the body count of frame {f + 1} of {num_frames}")
        frames.append(NTUFrame())
        for b in range(num_bodies):
            where = f"body {b + 1} of {num_bodies} in frame {f + 1}"
            values = lines.next(f"the body line of {where}").split()
            if len(values) != len(BODY_FIELDS):
                raise lines.error(f"expected the body line of {where}: {len(BODY_FIELDS)} values "
                                  f"({' '.join(BODY_FIELDS)}), got {len(values)}")  # fmt: skip
            try:
                body_id = int(values[0])
                info = np.array(values[1:], dtype=np.float64)
            except ValueError:
                raise lines.error(f"expected the body line of {where} (integer bodyID, then 9 numbers), "
                                  f"got {' '.join(values)!r}") from None  # fmt: skip
            if not np.isfinite(info).all():
                raise lines.error(f"the body line of {where} holds a non-finite number: {' '.join(values)!r}")
            joint_count = lines.count(f"the joint count of {where}")
            if joint_count != NUM_JOINTS:
                raise lines.error(f"expected the joint count of {where} = {NUM_JOINTS}, got {joint_count}")
            blocks.append((lines.skip_joints(where), where))
            records.append((f, timeline, body_id, info))
        if num_bodies:
            timeline += 1
    rest = [i for i in range(lines.pos, len(lines.lines)) if lines.lines[i].strip()]
    if rest:
        raise lines.error(f"unexpected content after the last of {num_frames} frames", rest[0] + 1)
    joints = lines.parse_all_joints(blocks) if blocks else np.zeros((0, NUM_JOINTS, len(JOINT_FIELDS)))
    lines.check_finite_joints(joints, blocks)
    tracks: dict[int, dict] = {}
    for (f, step, body_id, info), body_joints in zip(records, joints):
        frames[f].bodies.append(NTUBodyFrame(body_id, info, body_joints))
        track = tracks.setdefault(body_id, {"start": step, "frames": [], "xyz": []})
        if not track["frames"] or track["frames"][-1] != f:  # an id repeated in a frame: keep the first
            track["frames"].append(f)
            track["xyz"].append(body_joints[:, :3])
    bodies = []
    for body_id, track in tracks.items():
        xyz = np.stack(track["xyz"]).astype(np.float32)
        bodies.append(NTUBody(body_id, track["start"], track["frames"], xyz, _motion(xyz)))
    return NTUSequence(path_str, frames, bodies)


@MOTION_FORMATS.register(".skeleton")
def read_ntu_motion(path: Path, request: ReadRequest) -> FileMotion:
    """a raw NTU RGB+D ``.skeleton`` file (every tracked body, up to two, 30 fps)"""
    keypoints = read_skeleton_file(path).keypoints(max_bodies=2)  # (M, T, 25, 3)
    if keypoints.shape[1] == 0:
        raise ValueError(f"{path}: no frame lists a body")
    skel = get_skeleton("ntu25")
    bodies = keypoints.shape[0]
    # Bodies side by side in one joint array; each keeps its own root (the camera follows the first).
    parents = [p + b * skel.num_joints if p >= 0 else -1 for b in range(bodies) for p in skel.parents]
    joints = np.concatenate(list(keypoints), axis=1).astype(np.float64)
    names = [n for _ in range(bodies) for n in skel.joint_names]
    return FileMotion(JointsClip(joints, parents, names, request.motion_fps or 30.0))
