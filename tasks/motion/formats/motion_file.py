"""Our motion file format: ``.npz`` with AIST++-compatible keys.

Keys (read with ``allow_pickle=False``; units metres, seconds, radians; y-up):

=================  =============  ==========================================================
key                shape          meaning
=================  =============  ==========================================================
``smpl_poses``     (T, 72)        SMPL local axis-angle rotations (joint 0 = root orientation)
``smpl_trans``     (T, 3)         root translation, in units of ``smpl_scaling``
``smpl_scaling``   (1,)           scale; the root position in metres is ``smpl_trans / smpl_scaling``
``fps``            ()             frame rate
``skeleton``       ()             skeleton name (``smpl24``, ``humanml3d22``, ``ntu25``, ...)
``joints``         (T, J, 3)      joint positions in metres, when known
=================  =============  ==========================================================

A file holds SMPL parameters (then ``skeleton`` is ``smpl24``), joint positions, or both. Reading checks
every array's header before inflating it (at most ``MAX_NPZ_MEMBER_BYTES`` each), refuses non-real dtypes
(complex, datetime, object, ...) and implausible magnitudes: positions beyond ``MAX_POSITION_M`` metres,
axis-angle rotations beyond :data:`MAX_ROTATION_RAD` radians, a scaling outside :data:`SCALING_RANGE`.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import NoReturn

import numpy as np
import torch

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.skeletons import get_skeleton
from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics_axis_angle
from skeleton_mamba.tasks.motion.formats.registry import MOTION_FORMATS, FileMotion, ReadRequest
from skeleton_mamba.tasks.motion.io.value_checks import (
    MAX_POSITION_M,
    check_fps,
    check_magnitude,
    check_real,
    load_npz,
    non_finite_message,
)

__all__ = ["MAX_ROTATION_RAD", "SCALING_RANGE", "MotionData", "MotionFileError", "save_motion", "load_motion"]

MAX_ROTATION_RAD = 1000.0  # |axis-angle component|: a rotation is at most pi, wrapped ones a few turns
SCALING_RANGE = (1e-6, 1e6)  # smpl_scaling (AIST++ stores about 90 to 100)


class MotionFileError(DataFileError):
    """A motion file is missing keys or has inconsistent shapes (the message names the file)."""


@dataclass
class MotionData:
    """One motion clip.

    Attributes:
        fps: frames per second.
        skeleton: skeleton name (see :func:`skeleton_mamba.skeletons.get_skeleton`).
        poses: (T, 24, 3) SMPL axis-angle poses, or None.
        trans: (T, 3) root translation (``smpl_trans``), or None.
        scaling: ``smpl_scaling``; root position in metres = ``trans / scaling``.
        joints: (T, J, 3) joint positions in metres, or None.
    """

    fps: float
    skeleton: str = "smpl24"
    poses: np.ndarray | None = None
    trans: np.ndarray | None = None
    scaling: float = 1.0
    joints: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.poses is not None and self.poses.ndim == 2 and self.poses.shape[1] == 72:
            self.poses = self.poses.reshape(-1, 24, 3)

    def validate(self, source: str = "<motion>") -> MotionData:
        """Check shapes and consistency; raises :class:`MotionFileError` naming ``source``."""

        def fail(msg: str) -> NoReturn:
            raise MotionFileError(f"{source}: {msg}")

        try:
            check_fps(self.fps, "fps")
        except ValueError as e:
            fail(str(e))
        try:
            skel = get_skeleton(self.skeleton)
        except KeyError as e:
            fail(str(e.args[0]))
        if self.poses is None and self.joints is None:
            fail("holds neither SMPL parameters (smpl_poses, smpl_trans) nor joints")
        lengths = set()
        if self.poses is not None:
            if skel.name != "smpl24":
                fail(f"smpl_poses given but skeleton is {skel.name!r} (SMPL parameters need 'smpl24')")
            if self.poses.ndim != 3 or self.poses.shape[1:] != (24, 3):
                fail(f"smpl_poses must be (T, 72) or (T, 24, 3), got {self.poses.shape}")
            if self.trans is None or self.trans.ndim != 2 or self.trans.shape[1] != 3:
                fail(f"smpl_trans must be (T, 3), got {None if self.trans is None else self.trans.shape}")
            if not (np.isfinite(self.scaling) and SCALING_RANGE[0] <= self.scaling <= SCALING_RANGE[1]):
                fail(f"smpl_scaling must be a number in {SCALING_RANGE[0]:g}-{SCALING_RANGE[1]:g}, "
                     f"got {self.scaling}")  # fmt: skip
            lengths |= {len(self.poses), len(self.trans)}
        if self.joints is not None:
            if self.joints.ndim != 3 or self.joints.shape[1:] != (skel.num_joints, 3):
                fail(f"joints must be (T, {skel.num_joints}, 3) for {skel.name}, got {self.joints.shape}")
            lengths.add(len(self.joints))
        if len(lengths) != 1:
            fail(f"arrays disagree on the number of frames: {sorted(lengths)}")
        if lengths == {0}:
            fail("motion has no frames")
        keys = {"poses": "smpl_poses", "trans": "smpl_trans", "joints": "joints"}
        for name, key in keys.items():
            value = getattr(self, name)
            if value is None:
                continue
            check_real(value, source, key, MotionFileError)
            message = non_finite_message(value, name, ("frame", "joint"))
            if message is not None:
                fail(message)
        if self.poses is not None:
            axes = ("frame", "joint", "axis")
            check_magnitude(self.poses, MAX_ROTATION_RAD, source, "smpl_poses", axes, MotionFileError, " rad")
            root = np.asarray(self.trans, dtype=np.float64) / self.scaling
            check_magnitude(root, MAX_POSITION_M, source, "root position (smpl_trans / smpl_scaling)",
                            ("frame", "axis"), MotionFileError, " m")  # fmt: skip
        if self.joints is not None:
            axes = ("frame", "joint", "axis")
            check_magnitude(self.joints, MAX_POSITION_M, source, "joints", axes, MotionFileError, " m")
        return self

    @property
    def num_frames(self) -> int:
        return len(self.poses) if self.poses is not None else len(self.joints)

    def root_position(self) -> np.ndarray:
        """(T, 3) root position in metres (``smpl_trans / smpl_scaling``)."""
        if self.trans is None:
            raise ValueError("motion has no SMPL translation")
        return self.trans / self.scaling

    def joint_positions(self) -> np.ndarray:
        """(T, J, 3) joint positions in metres: the stored joints, else SMPL forward kinematics."""
        if self.joints is not None:
            return self.joints

        poses = torch.from_numpy(np.asarray(self.poses, dtype=np.float64))
        root = torch.from_numpy(np.asarray(self.root_position(), dtype=np.float64))
        return smpl_forward_kinematics_axis_angle(poses, root).numpy().astype(np.float32)


def save_motion(path: str | PathLike[str], motion: MotionData) -> Path:
    """Validate and write ``motion`` as a compressed ``.npz`` (module docstring for keys), atomically.

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> motion = MotionData(fps=30.0, skeleton="smpl24", joints=np.zeros((4, 24, 3), np.float32))
        >>> path = save_motion(Path(tempfile.mkdtemp()) / "still.npz", motion)
        >>> path.name, load_motion(path).joints.shape
        ('still.npz', (4, 24, 3))
    """
    path = Path(path)
    motion.validate(str(path))
    arrays: dict[str, np.ndarray] = {
        "fps": np.asarray(float(motion.fps), dtype=np.float64),
        "skeleton": np.asarray(get_skeleton(motion.skeleton).name),
    }
    if motion.poses is not None:
        arrays["smpl_poses"] = np.asarray(motion.poses, dtype=np.float32).reshape(len(motion.poses), 72)
        arrays["smpl_trans"] = np.asarray(motion.trans, dtype=np.float32)
        arrays["smpl_scaling"] = np.asarray([motion.scaling], dtype=np.float32)
    if motion.joints is not None:
        arrays["joints"] = np.asarray(motion.joints, dtype=np.float32)
    with atomic_open(path, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path


def load_motion(path: str | PathLike[str]) -> MotionData:
    """Read and validate a motion ``.npz``; raises :class:`MotionFileError` naming the file.

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "clip.npz"
        >>> np.savez(path, fps=30.0, skeleton="smpl24", joints=np.zeros((5, 24, 3), np.float32))
        >>> motion = load_motion(path)
        >>> motion.fps, motion.skeleton, motion.joints.shape
        (30.0, 'smpl24', (5, 24, 3))
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such motion file")
    arrays = load_npz(path, MotionFileError, text_keys=("skeleton",))
    if "fps" not in arrays:
        raise MotionFileError(f"{path}: missing key 'fps' (keys: {sorted(arrays)})")
    has_poses = "smpl_poses" in arrays
    if has_poses and "smpl_trans" not in arrays:
        raise MotionFileError(f"{path}: has 'smpl_poses' but no 'smpl_trans'")
    poses = arrays.get("smpl_poses")
    scaling = arrays.get("smpl_scaling", np.ones(1))
    if scaling.size != 1:
        raise MotionFileError(f"{path}: smpl_scaling must hold one value, got shape {scaling.shape}")
    name = arrays.get("skeleton", np.asarray("smpl24"))
    if name.dtype.kind != "U" or name.size != 1 or name.dtype.itemsize > 4 * 64:
        raise MotionFileError(f"{path}: 'skeleton' must be one name of at most 64 characters, got "
                              f"{name.dtype} of shape {name.shape}")  # fmt: skip
    skeleton = str(name.reshape(-1)[0])
    if arrays["fps"].size != 1:
        raise MotionFileError(f"{path}: fps must be a single number, got shape {arrays['fps'].shape}")
    motion = MotionData(
        fps=float(arrays["fps"].reshape(-1)[0]),
        skeleton=skeleton,
        poses=poses,
        trans=arrays.get("smpl_trans"),
        scaling=float(scaling.reshape(-1)[0]),
        joints=arrays.get("joints"),
    )
    return motion.validate(str(path))


@MOTION_FORMATS.register(".npz")
def read_npz_motion(path: Path, request: ReadRequest) -> FileMotion:
    """our motion ``.npz`` (SMPL parameters and / or joints)"""
    return FileMotion(load_motion(path))
