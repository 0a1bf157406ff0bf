"""One reader for every motion file the toolkit takes, in metres (``sm export``, ``sm view``, ``sm render``,
``sm evaluate-dance``):

- ``.npz``: our motion format (:mod:`.motion_file`); SMPL-24 through forward kinematics when no joints;
- ``.pkl``: an AIST++ motion (60 fps, read with the restricted unpickler), through forward kinematics;
- ``.npy``: joint positions (T, J, 3); the skeleton is ``skeleton`` or inferred from J (22 HumanML3D,
  24 SMPL, 25 NTU, 18 OpenPose); its frame rate ``motion_fps`` (default 20 for HumanML3D, 30 otherwise);
  or de-normalised HumanML3D features (T, 263) (``new_joint_vecs``, ``sm generate``'s
  ``*_features.npy``), turned into the 22 joints by ``recover_from_ric`` at 20 fps;
- ``.bvh``: any BVH file (hierarchy from the file), its unit detected from the figure (:mod:`.units`);
- ``.skeleton``: a raw NTU RGB+D file (every tracked body, 30 fps);
- ``.glb``: a motion glTF as ``sm export`` writes it (:mod:`.gltf_read`).

:func:`load_joints` gives joint positions (:class:`JointsClip`), :func:`load_skeleton_motion` the joint tree
with rotations where the file has them (:class:`~.gltf.SkeletonMotion`). Both apply ``units`` / ``scale``
(:func:`~.units.choose_scale`) and carry the :class:`~.units.UnitScale` they used, for the commands to state.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from os import PathLike
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.errors import InputError
from skeleton_mamba.skeletons import get_skeleton
from skeleton_mamba.tasks.motion.formats.aistpp import load_aistpp_motion
from skeleton_mamba.tasks.motion.formats.bvh import load_bvh
from skeleton_mamba.tasks.motion.formats.gltf import (
    SkeletonMotion,
    check_skeleton_motion,
    from_joints,
    from_motion_data,
)
from skeleton_mamba.tasks.motion.formats.gltf_read import read_glb
from skeleton_mamba.tasks.motion.formats.humanml3d_features import (
    FEATURE_DIM,
    check_features,
    recover_from_ric,
)
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FPS as HUMANML3D_FPS
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.formats.ntu import read_skeleton_file
from skeleton_mamba.tasks.motion.formats.units import METRES, UnitScale, choose_scale
from skeleton_mamba.tasks.motion.io.value_checks import (
    MAX_POSITION_M,
    check_finite,
    check_magnitude,
    load_npy,
)

__all__ = ["MOTION_SUFFIXES", "JointsClip", "load_joints", "load_skeleton_motion"]

MOTION_SUFFIXES = (".npz", ".pkl", ".npy", ".bvh", ".skeleton", ".glb")
_BY_JOINT_COUNT = {22: "humanml3d22", 24: "smpl24", 25: "ntu25", 18: "openpose18"}
_DEFAULT_FPS = {"humanml3d22": 20.0}


@dataclass
class JointsClip:
    """Joint positions ready to draw: (T, J, 3) metres y-up, parents, names, frame rate, the scale applied."""

    joints: np.ndarray
    parents: list[int]
    names: list[str]
    fps: float
    scale: UnitScale = METRES


def _from_skeleton(joints: np.ndarray, skeleton: str, fps: float) -> JointsClip:
    skel = get_skeleton(skeleton)
    return JointsClip(joints, list(skel.parents), list(skel.joint_names), fps)


def _existing(path: str | PathLike[str]) -> Path:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such motion file")
    if path.suffix.lower() not in MOTION_SUFFIXES:
        raise ValueError(
            f"{path}: unsupported motion file type {path.suffix.lower()!r} ({', '.join(MOTION_SUFFIXES)})"
        )
    return path


def _joints_in_file_units(path: Path, skeleton: str | None, motion_fps: float | None) -> JointsClip:
    """Every format but BVH and glTF (read as skeleton motions), as joint positions in the file's units."""
    suffix = path.suffix.lower()
    if suffix == ".npz":
        motion = load_motion(path)
        return _from_skeleton(motion.joint_positions(), motion.skeleton, motion_fps or motion.fps)
    if suffix == ".pkl":
        motion = load_aistpp_motion(path)
        return _from_skeleton(motion.joint_positions(), "smpl24", motion_fps or motion.fps)
    if suffix == ".npy":
        joints = load_npy(path)
        if joints.ndim == 2 and joints.shape[1] == FEATURE_DIM:
            features = torch.from_numpy(check_features(joints, path).astype(np.float64))
            joints = recover_from_ric(features).numpy()
            joints = check_finite(joints, f"{path} (joints recovered)", "joints", ("frame", "joint"))
            return _from_skeleton(joints, "humanml3d22", motion_fps or HUMANML3D_FPS)
        if joints.ndim != 3 or joints.shape[2] != 3:
            raise ValueError(
                f"{path}: expected joint positions (T, J, 3) or HumanML3D features (T, {FEATURE_DIM}), "
                f"got shape {joints.shape}"
            )
        name = skeleton or _BY_JOINT_COUNT.get(joints.shape[1])
        if name is None:
            raise ValueError(f"{path}: cannot infer a skeleton for {joints.shape[1]} joints; pass --skeleton")
        skel = get_skeleton(name)
        if skel.num_joints != joints.shape[1]:
            raise ValueError(f"{path}: {joints.shape[1]} joints, skeleton {skel.name} has {skel.num_joints}")
        if joints.shape[0] == 0:
            raise InputError(f"{path}: a joints file of zero frames")
        fps = motion_fps or _DEFAULT_FPS.get(skel.name, 30.0)
        joints = check_finite(joints.astype(np.float64), str(path), "joints", ("frame", "joint"))
        check_magnitude(joints, MAX_POSITION_M, str(path), "joints", ("frame", "joint"), unit=" m")
        return _from_skeleton(joints, name, fps)
    keypoints = read_skeleton_file(path).keypoints(max_bodies=2)  # .skeleton: (M, T, 25, 3)
    if keypoints.shape[1] == 0:
        raise ValueError(f"{path}: no frame lists a body")
    skel = get_skeleton("ntu25")
    bodies = keypoints.shape[0]
    # Bodies side by side in one joint array; each keeps its own root (the camera follows the first).
    parents = [p + b * skel.num_joints if p >= 0 else -1 for b in range(bodies) for p in skel.parents]
    joints = np.concatenate(list(keypoints), axis=1).astype(np.float64)
    names = [n for _ in range(bodies) for n in skel.joint_names]
    return JointsClip(joints, parents, names, motion_fps or 30.0)


def load_skeleton_motion(
    path: str | PathLike[str],
    skeleton: str | None = None,
    motion_fps: float | None = None,
    units: str | None = None,
    scale: float | None = None,
) -> SkeletonMotion:
    """Any motion file (module docstring) as a joint tree in metres: rotations kept where the file has them
    (our SMPL ``.npz``, ``.pkl``, ``.bvh``, ``.glb``), joint positions as translations otherwise; checked as
    glTF needs it (:func:`~.gltf.check_skeleton_motion`: an :class:`~.errors.InputError` naming the file).

    Args:
        path: the motion file.
        skeleton: skeleton of a ``.npy`` joint file (else inferred from its joint count).
        motion_fps: the input's frame rate (replaces the file's).
        units: the input's length unit (:func:`~.units.choose_scale`).
        scale: the input's metres per unit, instead of ``units`` (:func:`~.units.choose_scale`).

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion
        >>> joints = np.zeros((4, 24, 3), np.float32)
        >>> joints[:, :, 1] = np.linspace(0.0, 1.7, 24)  # a standing column of joints, y up
        >>> path = Path(tempfile.mkdtemp()) / "clip.npz"
        >>> path = save_motion(path, MotionData(30.0, "smpl24", joints=joints))
        >>> motion = load_skeleton_motion(path)
        >>> motion.translations.shape, motion.rotations is None, motion.fps
        ((4, 24, 3), True, 30.0)
    """
    path = _existing(path)
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        bvh = load_bvh(path)
        root = bvh.parents.index(-1)
        has_position = [any(c.endswith("position") for c in chs) for chs in bvh.channels]
        has_position[root] = True
        unit = choose_scale(units, scale, bvh.rest_height())
        motion = SkeletonMotion(
            list(bvh.names),
            list(bvh.parents),
            bvh.fps,
            np.asarray(bvh.offsets, np.float64),
            bvh.local_translations(),
            bvh.local_rotations().numpy(),
            has_position,
        )
    elif suffix == ".glb":
        motion, unit = read_glb(path), choose_scale(units, scale)
    elif suffix in (".npz", ".pkl"):
        data = load_motion(path) if suffix == ".npz" else load_aistpp_motion(path)
        motion, unit = from_motion_data(data), choose_scale(units, scale)
    else:
        clip = _joints_in_file_units(path, skeleton, None)
        motion = from_joints(clip.joints, None, clip.fps, clip.parents, clip.names)
        unit = choose_scale(units, scale)
    s = unit.metres_per_unit
    scaled = replace(
        motion,
        fps=motion_fps or motion.fps,
        offsets=motion.offsets * s,
        translations=motion.translations * s,
        scale=unit,
    )
    return check_skeleton_motion(scaled, str(path))  # what glTF cannot hold, refused naming the file


def load_joints(
    path: str | PathLike[str],
    skeleton: str | None = None,
    motion_fps: float | None = None,
    units: str | None = None,
    scale: float | None = None,
) -> JointsClip:
    """Any motion file (module docstring) as joint positions in metres; arguments as
    :func:`load_skeleton_motion`.

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "clip.npy"  # joint positions (T, J, 3); 24 joints: SMPL-24
        >>> joints = np.zeros((4, 24, 3), np.float32)
        >>> joints[:, :, 1] = np.linspace(0.0, 1.7, 24)  # a standing column of joints, y up
        >>> np.save(path, joints)
        >>> clip = load_joints(path, motion_fps=30.0)
        >>> clip.joints.shape, clip.fps, len(clip.parents), clip.names[0]
        ((4, 24, 3), 30.0, 24, 'pelvis')
    """
    path = _existing(path)
    if path.suffix.lower() in (".bvh", ".glb"):
        motion = load_skeleton_motion(path, skeleton, motion_fps, units, scale)
        return JointsClip(motion.joint_positions(), motion.parents, motion.names, motion.fps, motion.scale)
    clip = _joints_in_file_units(path, skeleton, motion_fps)
    unit = choose_scale(units, scale)
    return replace(clip, joints=clip.joints * unit.metres_per_unit, scale=unit)
