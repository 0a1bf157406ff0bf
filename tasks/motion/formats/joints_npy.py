"""Joint positions in a ``.npy`` file: (T, J, 3) joints of a known skeleton, or de-normalised HumanML3D
features (T, 263) (``new_joint_vecs``, ``sm generate``'s ``*_features.npy``), turned into the 22 joints by
``recover_from_ric`` at 20 fps.

The skeleton is the request's, or inferred from J (22 HumanML3D, 24 SMPL, 25 NTU, 18 OpenPose); the frame
rate the request's, or 20 fps for HumanML3D and 30 otherwise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.errors import InputError
from skeleton_mamba.skeletons import get_skeleton
from skeleton_mamba.tasks.motion.formats.humanml3d_features import (
    FEATURE_DIM,
    check_features,
    recover_from_ric,
)
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FPS as HUMANML3D_FPS
from skeleton_mamba.tasks.motion.formats.registry import MOTION_FORMATS, FileMotion, JointsClip, ReadRequest
from skeleton_mamba.tasks.motion.io.value_checks import (
    MAX_POSITION_M,
    check_finite,
    check_magnitude,
    load_npy,
)

__all__ = ["SKELETON_BY_JOINT_COUNT", "read_npy_joints"]

SKELETON_BY_JOINT_COUNT = {22: "humanml3d22", 24: "smpl24", 25: "ntu25", 18: "openpose18"}
_DEFAULT_FPS = {"humanml3d22": HUMANML3D_FPS}


@MOTION_FORMATS.register(".npy")
def read_npy_joints(path: Path, request: ReadRequest) -> FileMotion:
    """joint positions (T, J, 3) or HumanML3D features (T, 263) in a ``.npy``"""
    joints = load_npy(path)
    if joints.ndim == 2 and joints.shape[1] == FEATURE_DIM:
        features = torch.from_numpy(check_features(joints, path).astype(np.float64))
        joints = recover_from_ric(features).numpy()
        joints = check_finite(joints, f"{path} (joints recovered)", "joints", ("frame", "joint"))
        return FileMotion(JointsClip.of_skeleton(joints, "humanml3d22", request.motion_fps or HUMANML3D_FPS))
    if joints.ndim != 3 or joints.shape[2] != 3:
        raise ValueError(
            f"{path}: expected joint positions (T, J, 3) or HumanML3D features (T, {FEATURE_DIM}), "
            f"got shape {joints.shape}"
        )
    name = request.skeleton or SKELETON_BY_JOINT_COUNT.get(joints.shape[1])
    if name is None:
        raise ValueError(f"{path}: cannot infer a skeleton for {joints.shape[1]} joints; pass --skeleton")
    skel = get_skeleton(name)
    if skel.num_joints != joints.shape[1]:
        raise ValueError(f"{path}: {joints.shape[1]} joints, skeleton {skel.name} has {skel.num_joints}")
    if joints.shape[0] == 0:
        raise InputError(f"{path}: a joints file of zero frames")
    fps = request.motion_fps or _DEFAULT_FPS.get(skel.name, 30.0)
    joints = check_finite(joints.astype(np.float64), str(path), "joints", ("frame", "joint"))
    check_magnitude(joints, MAX_POSITION_M, str(path), "joints", ("frame", "joint"), unit=" m")
    return FileMotion(JointsClip.of_skeleton(joints, name, fps))
