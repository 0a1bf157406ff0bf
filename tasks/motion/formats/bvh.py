"""BVH (Biovision Hierarchy) motion files: read any joint tree and Euler order, write SMPL-24 motion.

Format: a ``HIERARCHY`` section with one ``ROOT`` and nested ``JOINT`` / ``End Site`` blocks, each
with an ``OFFSET x y z`` (from the parent, in the parent's rest frame) and, except end sites,
``CHANNELS n name...``; then ``MOTION``, ``Frames: N``, ``Frame Time: dt`` and N lines of channel
values in hierarchy order. Rotation channels are degrees; a joint's local rotation is the product of
its elementary rotations in channel order (``Zrotation Xrotation Yrotation`` -> ``Rz @ Rx @ Ry``).
Position channels replace the joint's offset (the usual reading: the root's channels are its
position). Units are the file's own (CMU files are not in metres): pass ``scale`` to convert;
:meth:`BvhMotion.rest_height` is what :mod:`.units` detects the unit from.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.body.kinematics import forward_kinematics
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix, euler_to_matrix, matrix_to_euler
from skeleton_mamba.tasks.motion.body.smpl import SMPL_REST_OFFSETS
from skeleton_mamba.tasks.motion.formats.gltf import SkeletonMotion
from skeleton_mamba.tasks.motion.formats.registry import MOTION_FORMATS, FileMotion, ReadRequest
from skeleton_mamba.tasks.motion.io.value_checks import FPS_RANGE

__all__ = ["BvhError", "BvhMotion", "load_bvh", "save_bvh", "smpl_to_bvh", "bvh_to_smpl"]

# |value| of any BVH number (offsets and positions in file units, often centimetres: 1000 km; rotations in
# degrees) beyond which a file is corrupt or hostile: sums of such values stay far inside float32
MAX_BVH_VALUE = 1e8
_ROT = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}


class BvhError(DataFileError):
    """A BVH file is malformed (the message names the file and line)."""


@dataclass
class BvhMotion:
    """A parsed BVH file.

    Attributes:
        names: J joint names (end sites excluded).
        parents: J parent indices, ``-1`` for the root; parents precede children.
        offsets: (J, 3) rest offsets in file units.
        channels: per joint, its channel names in file order.
        frame_time: seconds per frame.
        values: (T, C) channel values in file order (rotations in degrees).
        end_sites: joint index -> (3,) offset of the end site below it.
    """

    names: list[str]
    parents: list[int]
    offsets: np.ndarray
    channels: list[tuple[str, ...]]
    frame_time: float
    values: np.ndarray
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return self.values.shape[0]

    @property
    def fps(self) -> float:
        """``1 / frame_time``, rounded to an integer when within 0.01 % of one (``.0083333`` -> 120)."""
        fps = 1.0 / self.frame_time
        return float(round(fps)) if abs(fps - round(fps)) < 1e-4 * fps else fps

    def _channel_columns(self) -> list[list[int]]:
        cols, start = [], 0
        for ch in self.channels:
            cols.append(list(range(start, start + len(ch))))
            start += len(ch)
        return cols

    def select_frames(self, index: slice | Sequence[int]) -> BvhMotion:
        """A copy holding only the frames ``values[index]`` (same hierarchy)."""
        return replace(self, values=self.values[index].reshape(-1, self.values.shape[1]))

    def local_rotations(self) -> torch.Tensor:
        """(T, J, 3, 3) float64 local rotations from the rotation channels (identity when none)."""
        out = torch.eye(3, dtype=torch.float64).repeat(self.num_frames, len(self.names), 1, 1)
        values = torch.from_numpy(self.values)
        groups: dict[str, tuple[list[int], list[list[int]]]] = {}  # Euler order -> joints, their columns
        for j, (chs, cols) in enumerate(zip(self.channels, self._channel_columns())):
            rot = [(c, col) for c, col in zip(chs, cols) if c in _ROT]
            if rot:
                joints, columns = groups.setdefault("".join(_ROT[c] for c, _ in rot), ([], []))
                joints.append(j)
                columns.append([col for _, col in rot])
        for order, (joints, columns) in groups.items():  # one batched conversion per Euler order
            out[:, joints] = euler_to_matrix(torch.deg2rad(values[:, columns]), order)
        return out

    def local_translations(self) -> np.ndarray:
        """(T, J, 3) per-frame offsets: the rest offsets with position channels substituted."""
        out = np.repeat(self.offsets[None], self.num_frames, axis=0).astype(np.float64)
        for j, (chs, cols) in enumerate(zip(self.channels, self._channel_columns())):
            for c, col in zip(chs, cols):
                if c in _POS:
                    out[:, j, _POS[c]] = self.values[:, col]
        return out

    def rest_height(self) -> float:
        """The figure's size at rest in file units: the largest extent, over x, y and z, of the rest pose's
        joints and end sites (its height whichever axis is up; a T-pose's arm span is about the same)."""
        rotations = torch.eye(3, dtype=torch.float64).expand(len(self.names), 3, 3)
        offsets = torch.from_numpy(np.asarray(self.offsets, np.float64))
        root = torch.zeros(3, dtype=torch.float64)
        positions = forward_kinematics(rotations, root, offsets, self.parents)[0]
        points = [positions.numpy()] + [positions[j].numpy() + site for j, site in self.end_sites.items()]
        points = np.vstack([np.reshape(p, (-1, 3)) for p in points])
        return float(np.ptp(points, axis=0).max())

    def joint_positions(self, scale: float = 1.0) -> np.ndarray:
        """(T, J, 3) world joint positions (file units times ``scale``) by forward kinematics."""
        trans = torch.from_numpy(self.local_translations())
        root = self.parents.index(-1)
        positions, _ = forward_kinematics(self.local_rotations(), trans[:, root], trans, self.parents)
        return positions.numpy() * scale


def _fail(source: str, line: int, msg: str) -> BvhError:
    return BvhError(f"{source}:{line}: {msg}")


def _floats(tokens: list[str], n: int, source: str, line: int) -> np.ndarray:
    try:
        values = [float(t) for t in tokens]
    except ValueError:
        raise _fail(source, line, f"expected {n} numbers, got {' '.join(tokens)!r}") from None
    if len(values) != n:
        raise _fail(source, line, f"expected {n} numbers, got {len(values)}")
    if not all(map(math.isfinite, values)):
        raise _fail(source, line, f"expected {n} finite numbers, got {' '.join(tokens)!r}")
    if any(abs(v) > MAX_BVH_VALUE for v in values):
        raise _fail(source, line, f"{' '.join(tokens)!r}: beyond the plausible {MAX_BVH_VALUE:g}")
    return np.asarray(values)


def _parse(text: str, source: str) -> BvhMotion:
    lines = text.splitlines()
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[tuple[str, ...]] = []
    end_sites: dict[int, np.ndarray] = {}
    stack: list[int] = []  # joint index per open brace; -2 for an end site
    pending: int | None = None  # joint whose "{" is expected next
    i = 0
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i == len(lines) or lines[i].strip() != "HIERARCHY":
        raise _fail(source, i + 1, "file must start with HIERARCHY")
    i += 1
    while i < len(lines):
        tokens = lines[i].split()
        i += 1
        if not tokens:
            continue
        key = tokens[0]
        if key in ("ROOT", "JOINT"):
            if (key == "ROOT") != (not stack):
                raise _fail(source, i, f"{key} {' '.join(tokens[1:])} at the wrong nesting level")
            if stack and stack[-1] < 0:
                raise _fail(source, i, "JOINT inside an End Site")
            if key == "ROOT" and names:
                raise _fail(source, i, "only one ROOT is supported")
            names.append(" ".join(tokens[1:]) or f"joint{len(names)}")
            parents.append(stack[-1] if stack else -1)
            offsets.append(np.zeros(3))
            channels.append(())
            pending = len(names) - 1
        elif key == "End" and tokens[1:2] == ["Site"]:
            if not stack or stack[-1] < 0:
                raise _fail(source, i, "End Site outside a joint")
            pending = -2
        elif key == "{":
            if pending is None:
                raise _fail(source, i, "unexpected '{'")
            stack.append(pending if pending >= 0 else -2 - stack[-1])  # end site: -2 - owner
            pending = None
        elif key == "}":
            if not stack:
                raise _fail(source, i, "unbalanced '}'")
            stack.pop()
        elif key == "OFFSET":
            if not stack:
                raise _fail(source, i, "OFFSET outside a joint")
            value = _floats(tokens[1:], 3, source, i)
            if stack[-1] >= 0:
                offsets[stack[-1]] = value
            else:
                end_sites[-2 - stack[-1]] = value
        elif key == "CHANNELS":
            if not stack or stack[-1] < 0:
                raise _fail(source, i, "CHANNELS outside a joint")
            try:
                n = int(tokens[1])
            except (IndexError, ValueError):
                raise _fail(source, i, "CHANNELS needs a count") from None
            chs = tuple(tokens[2:])
            unknown = [c for c in chs if c not in _ROT and c not in _POS]
            if len(chs) != n or unknown:
                raise _fail(source, i, f"bad CHANNELS line (count {n}, names {list(chs)})")
            channels[stack[-1]] = chs
        elif key == "MOTION":
            break
        else:
            raise _fail(source, i, f"unexpected {key!r} in HIERARCHY")
    else:
        raise _fail(source, i, "no MOTION section")
    if stack or not names:
        raise _fail(source, i, "unbalanced braces or empty hierarchy before MOTION")

    def header(prefix: str) -> str:
        nonlocal i
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i == len(lines) or not lines[i].strip().startswith(prefix):
            raise _fail(source, i + 1, f"expected '{prefix}'")
        i += 1
        return lines[i - 1].strip()[len(prefix) :].strip()

    try:
        num_frames = int(header("Frames:"))
        frame_time = float(header("Frame Time:"))
    except ValueError as e:
        raise _fail(source, i, f"bad Frames / Frame Time value ({e})") from None
    if num_frames < 1:
        raise _fail(source, i - 1, f"Frames says {num_frames}: a BVH file needs at least one frame of motion")
    low, high = 1.0 / FPS_RANGE[1], 1.0 / FPS_RANGE[0]
    if not low <= frame_time <= high:  # NaN fails too
        raise _fail(source, i, f"Frame Time {frame_time} s is outside [{low:g}, {high:g}] s "
                               f"({FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} frames per second)")  # fmt: skip
    num_channels = sum(len(c) for c in channels)
    rows = [(n + 1, ln) for n, ln in enumerate(lines[i:], start=i) if ln.strip()]
    if len(rows) != num_frames:
        raise _fail(source, i, f"Frames says {num_frames} but {len(rows)} data lines follow")
    try:
        values = np.loadtxt(io.StringIO("\n".join(ln for _, ln in rows)), ndmin=2).reshape(num_frames, -1)
    except ValueError as e:
        raise _fail(source, i + 1, f"motion data is not {num_channels} numbers per line ({e})") from None
    if values.shape[1] != num_channels:
        msg = f"motion lines have {values.shape[1]} values, channels need {num_channels}"
        raise _fail(source, i + 1, msg)
    with np.errstate(invalid="ignore"):
        bad = np.argwhere(~(np.abs(values) <= MAX_BVH_VALUE))  # NaN fails the comparison too
    if len(bad):
        frame, column = bad[0]
        value = values[frame, column]
        why = (
            "NaN and Inf are refused" if not np.isfinite(value) else f"beyond the plausible {MAX_BVH_VALUE:g}"
        )
        raise _fail(source, rows[frame][0], f"frame {frame + 1}, channel {column + 1}: {value:g} ({why})")
    return BvhMotion(names, parents, np.stack(offsets), channels, frame_time, values, end_sites)


def load_bvh(path: str | PathLike[str]) -> BvhMotion:
    """Parse a BVH file; raises :class:`BvhError` naming the file and line on malformed input.

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> lines = [
        ...     "HIERARCHY", "ROOT hips", "{", "OFFSET 0 0 0",
        ...     "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
        ...     "JOINT spine", "{", "OFFSET 0 10 0", "CHANNELS 3 Zrotation Xrotation Yrotation",
        ...     "End Site", "{", "OFFSET 0 5 0", "}", "}", "}",
        ...     "MOTION", "Frames: 2", "Frame Time: 0.0333333", "0 90 0 0 0 0 0 0 0", "1 90 0 0 0 0 0 45 0",
        ... ]
        >>> path = Path(tempfile.mkdtemp()) / "two_joints.bvh"
        >>> _ = path.write_text("\\n".join(lines) + "\\n")
        >>> motion = load_bvh(path)
        >>> motion.names, motion.parents, motion.num_frames, motion.fps
        (['hips', 'spine'], [-1, 0], 2, 30.0)
        >>> motion.values.shape, float(motion.values[1, -2])  # spine's Xrotation, frame 1
        ((2, 9), 45.0)
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such BVH file")
    return _parse(path.read_text(encoding="utf-8", errors="replace"), str(path))


def _fmt(v: np.ndarray) -> str:
    return " ".join(f"{x:.6f}" for x in v)


def save_bvh(path: str | PathLike[str], motion: BvhMotion) -> Path:
    """Write ``motion`` as standard BVH text (tabs, ROOT/JOINT/End Site, one frame per line).

    Joints are written depth-first, so reading the file back gives the joints in depth-first order
    (the index order of ``motion`` when it already is, as for files read with :func:`load_bvh`).

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> lines = [
        ...     "HIERARCHY", "ROOT pelvis", "{", "OFFSET 0 0 0",
        ...     "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
        ...     "End Site", "{", "OFFSET 0 5 0", "}", "}",
        ...     "MOTION", "Frames: 1", "Frame Time: 0.0333333", "0 90 0 0 45 0",
        ... ]
        >>> path = Path(tempfile.mkdtemp()) / "one_joint.bvh"
        >>> _ = path.write_text("\\n".join(lines) + "\\n")
        >>> motion = load_bvh(path)
        >>> copy = load_bvh(save_bvh(path.with_name("copy.bvh"), motion))
        >>> copy.names == motion.names and bool((copy.values == motion.values).all())
        True
    """
    path = Path(path)
    children: dict[int, list[int]] = {j: [] for j in range(len(motion.names))}
    for j, p in enumerate(motion.parents):
        if p >= 0:
            children[p].append(j)
    out = ["HIERARCHY"]
    written: list[int] = []  # joints in file (depth-first) order

    def write(j: int, depth: int) -> None:
        written.append(j)
        tab = "\t" * depth
        out.append(f"{tab}{'ROOT' if motion.parents[j] < 0 else 'JOINT'} {motion.names[j]}")
        out.append(f"{tab}{{")
        out.append(f"{tab}\tOFFSET {_fmt(motion.offsets[j])}")
        out.append(f"{tab}\tCHANNELS {len(motion.channels[j])} {' '.join(motion.channels[j])}".rstrip())
        for c in children[j]:
            write(c, depth + 1)
        if j in motion.end_sites:
            site = _fmt(motion.end_sites[j])
            out.extend([f"{tab}\tEnd Site", f"{tab}\t{{", f"{tab}\t\tOFFSET {site}", f"{tab}\t}}"])
        out.append(f"{tab}}}")

    if any(p >= j for j, p in enumerate(motion.parents)):
        raise ValueError("save_bvh needs parents before children (hierarchy order)")
    write(motion.parents.index(-1), 0)
    out += ["MOTION", f"Frames: {motion.num_frames}", f"Frame Time: {motion.frame_time:.8f}"]
    # Channel values follow the file's joint order, which is depth-first, not necessarily index order.
    columns = motion._channel_columns()
    order = [c for j in written for c in columns[j]]
    buf = io.StringIO()
    np.savetxt(buf, motion.values[:, order], fmt="%.6f")
    with atomic_open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(out) + "\n" + buf.getvalue())
    return path


def smpl_to_bvh(
    poses: torch.Tensor | np.ndarray,
    root_position: torch.Tensor | np.ndarray,
    fps: float,
    offsets: np.ndarray | None = None,
    order: str = "ZXY",
    scale: float = 1.0,
) -> BvhMotion:
    """SMPL-24 motion as a BVH skeleton (root: 6 channels, others: 3 rotation channels in ``order``).

    Args:
        poses: (T, 24, 3) axis-angle or (T, 24, 3, 3) rotation matrices (local, SMPL order).
        root_position: (T, 3) pelvis position in metres (``smpl_trans / smpl_scaling``).
        fps: frame rate.
        offsets: (24, 3) rest offsets in metres; default the SMPL table of
            :mod:`skeleton_mamba.tasks.motion.body.smpl`.
        order: Euler order of the rotation channels.
        scale: file units per metre (1 = metres; 100 = centimetres).

    Leaf joints (toes, head, hands) get an End Site half as long as their own bone, continuing it.
    """

    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps}")
    rot = torch.as_tensor(poses, dtype=torch.float64)
    if rot.dim() == 3 and rot.shape[-1] == 3:
        rot = axis_angle_to_matrix(rot)
    if rot.dim() != 4 or rot.shape[1:] != (24, 3, 3):
        raise ValueError(f"SMPL poses must be (T, 24, 3) axis-angle or (T, 24, 3, 3), got {tuple(rot.shape)}")
    root = np.asarray(root_position, dtype=np.float64).reshape(-1, 3)
    if len(root) != len(rot):
        raise ValueError(f"poses have {len(rot)} frames but root_position has {len(root)}")
    offs = np.asarray(SMPL_REST_OFFSETS if offsets is None else offsets, dtype=np.float64) * scale
    order = order.upper()
    euler = np.rad2deg(matrix_to_euler(rot, order))  # (T, 24, 3)
    values = np.concatenate([root * scale, euler.reshape(len(rot), -1)], axis=1)
    rot_names = tuple(f"{a}rotation" for a in order)
    channels = [("Xposition", "Yposition", "Zposition", *rot_names)] + [rot_names] * 23
    has_child = {p for p in SMPL24.parents if p >= 0}
    end_sites = {j: 0.5 * offs[j] for j in range(24) if j not in has_child}
    return BvhMotion(
        names=list(SMPL24.joint_names),
        parents=list(SMPL24.parents),
        offsets=offs,
        channels=channels,
        frame_time=1.0 / fps,
        values=values,
        end_sites=end_sites,
    )


def bvh_to_smpl(motion: BvhMotion, scale: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
    """SMPL-24 rotations and root position from a BVH whose joints carry the SMPL-24 names.

    The inverse of :func:`smpl_to_bvh` (files written by it, in any joint order).

    Args:
        motion: a BVH with the 24 joint names of :data:`~skeleton_mamba.skeletons.SMPL24`.
        scale: metres per file unit (1 / the ``scale`` used when writing).

    Returns:
        ``(rotations, root_position)``: (T, 24, 3, 3) local rotations in SMPL order and (T, 3) metres.
    """
    missing = [n for n in SMPL24.joint_names if n not in motion.names]
    if missing:
        raise ValueError(f"BVH lacks SMPL-24 joints {missing}")
    index = [motion.names.index(n) for n in SMPL24.joint_names]
    rotations = motion.local_rotations()[:, index]
    root = torch.from_numpy(motion.local_translations()[:, index[0]]) * scale
    return rotations, root


@MOTION_FORMATS.register(".bvh")
def read_bvh_motion(path: Path, request: ReadRequest) -> FileMotion:
    """any BVH file (hierarchy from the file; its unit detected from the figure's height)"""
    bvh = load_bvh(path)
    root = bvh.parents.index(-1)
    has_position = [any(c.endswith("position") for c in chs) for chs in bvh.channels]
    has_position[root] = True
    motion = SkeletonMotion(
        list(bvh.names),
        list(bvh.parents),
        bvh.fps,
        np.asarray(bvh.offsets, np.float64),
        bvh.local_translations(),
        bvh.local_rotations().numpy(),
        has_position,
    )
    return FileMotion(motion, figure_height=bvh.rest_height())
