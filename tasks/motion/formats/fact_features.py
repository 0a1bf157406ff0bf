"""The 219-d QEAN/FACT motion vector of AIST++ SMPL parameters, and back.

Per frame: ``[root translation (3) | 24 local rotation matrices, row-major (216)]``; the translation is
``smpl_trans / smpl_scaling`` (metres, y-up), 60 fps. This is FACT's 225-d vector without its six leading
zeros (google-research/mint; [QEAN] Sec. 4.2 gives "9-d rotation matrices of 24 joints + 3-d
translation"). Rotations use the toolkit's kornia conversions. Decoding projects each predicted 3x3 block
to the nearest rotation (``U diag(1, 1, det(U V^T)) V^T`` from its SVD), as the FACT metric scripts do.
"""

from __future__ import annotations

import numpy as np
import torch

from skeleton_mamba.tasks.motion.body.resample import resample_smpl
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData

__all__ = [
    "FPS",
    "MOTION_DIM",
    "features_to_joints",
    "features_to_smpl",
    "motion_to_features",
    "nearest_rotation",
    "smpl_to_features",
]

FPS = 60.0
MOTION_DIM = 219


def smpl_to_features(poses: torch.Tensor, root: torch.Tensor) -> torch.Tensor:
    """Axis-angle poses (..., T, 24, 3) or (..., T, 72) and root position (..., T, 3) -> (..., T, 219)."""
    if poses.shape[-1] == 72:
        poses = poses.reshape(*poses.shape[:-1], 24, 3)
    if poses.shape[-2:] != (24, 3) or root.shape[-1] != 3:
        raise ValueError(
            f"expected poses (..., 24, 3) and root (..., 3), got {tuple(poses.shape)}, {tuple(root.shape)}"
        )
    rot = axis_angle_to_matrix(poses).flatten(-3)  # (..., T, 216), row-major per joint
    return torch.cat([root.to(rot.dtype), rot], dim=-1)


def nearest_rotation(matrix: torch.Tensor) -> torch.Tensor:
    """The rotation closest (Frobenius) to each (..., 3, 3) matrix: ``U diag(1, 1, det) V^T``."""
    u, _, vh = torch.linalg.svd(matrix)
    det = torch.det(u @ vh)
    fix = torch.ones_like(matrix[..., 0])
    fix[..., 2] = det
    return (u * fix.unsqueeze(-2)) @ vh


def _split(features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    if features.shape[-1] != MOTION_DIM:
        raise ValueError(f"expected (..., {MOTION_DIM}) motion features, got {tuple(features.shape)}")
    rot = nearest_rotation(features[..., 3:].reshape(*features.shape[:-1], 24, 3, 3))
    return rot, features[..., :3]


def features_to_smpl(features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., T, 219) -> axis-angle poses (..., T, 24, 3) and root position (..., T, 3)."""
    rot, root = _split(features)
    return matrix_to_axis_angle(rot), root


def features_to_joints(features: torch.Tensor) -> torch.Tensor:
    """(..., T, 219) -> SMPL-24 joint positions (..., T, 24, 3) by the toolkit's offset-table FK."""
    rot, root = _split(features)
    return smpl_forward_kinematics(rot, root)


def motion_to_features(motion: MotionData, fps: float = FPS) -> torch.Tensor:
    """A :class:`MotionData` with SMPL parameters -> (T, 219) float32 at ``fps`` (resampled if needed)."""
    if motion.poses is None or motion.trans is None:
        raise ValueError("QEAN needs SMPL parameters (smpl_poses, smpl_trans); the motion has joints only")
    poses = torch.from_numpy(np.asarray(motion.poses, dtype=np.float64))
    root = torch.from_numpy(np.asarray(motion.root_position(), dtype=np.float64))
    if motion.fps != fps:
        poses, root = resample_smpl(poses, root, motion.fps, fps)
    return smpl_to_features(poses, root).float()
