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

A file holds SMPL parameters (then ``skeleton`` is ``smpl24``), joint positions, or both.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import NoReturn

import numpy as np
import torch

from skeleton_mamba.skeletons import get_skeleton
from skeleton_mamba.tasks.motion.atomic import atomic_open
from skeleton_mamba.tasks.motion.errors import DataFileError
from skeleton_mamba.tasks.motion.smpl import smpl_forward_kinematics_axis_angle
from skeleton_mamba.tasks.motion.value_checks import check_fps, non_finite_message

__all__ = ["MotionData", "MotionFileError", "save_motion", "load_motion"]


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
            if not (np.isfinite(self.scaling) and self.scaling > 0):
                fail(f"smpl_scaling must be a positive number, got {self.scaling}")
            lengths |= {len(self.poses), len(self.trans)}
        if self.joints is not None:
            if self.joints.ndim != 3 or self.joints.shape[1:] != (skel.num_joints, 3):
                fail(f"joints must be (T, {skel.num_joints}, 3) for {skel.name}, got {self.joints.shape}")
            lengths.add(len(self.joints))
        if len(lengths) != 1:
            fail(f"arrays disagree on the number of frames: {sorted(lengths)}")
        if lengths == {0}:
            fail("motion has no frames")
        for name in ("poses", "trans", "joints"):
            value = getattr(self, name)
            message = None if value is None else non_finite_message(value, name, ("frame", "joint"))
            if message is not None:
                fail(message)
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
    """Validate and write ``motion`` as a compressed ``.npz`` (module docstring for keys), atomically."""
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
    """Read and validate a motion ``.npz``; raises :class:`MotionFileError` naming the file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such motion file")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as e:
        raise MotionFileError(f"{path}: not a readable .npz motion file ({e})") from e
    if "fps" not in arrays:
        raise MotionFileError(f"{path}: missing key 'fps' (keys: {sorted(arrays)})")
    has_poses = "smpl_poses" in arrays
    if has_poses and "smpl_trans" not in arrays:
        raise MotionFileError(f"{path}: has 'smpl_poses' but no 'smpl_trans'")
    poses = arrays.get("smpl_poses")
    scaling = arrays.get("smpl_scaling", np.ones(1))
    if scaling.size != 1:
        raise MotionFileError(f"{path}: smpl_scaling must hold one value, got shape {scaling.shape}")
    skeleton = str(arrays["skeleton"]) if "skeleton" in arrays else "smpl24"
    if arrays["fps"].size != 1:
        raise MotionFileError(f"{path}: fps must be a single number, got shape {arrays['fps'].shape}")
    for key, value in arrays.items():
        if key != "skeleton" and not np.issubdtype(value.dtype, np.number):
            raise MotionFileError(f"{path}: {key!r} must be numeric, got dtype {value.dtype}")
    motion = MotionData(
        fps=float(arrays["fps"].reshape(-1)[0]),
        skeleton=skeleton,
        poses=poses,
        trans=arrays.get("smpl_trans"),
        scaling=float(scaling.reshape(-1)[0]),
        joints=arrays.get("joints"),
    )
    return motion.validate(str(path))
