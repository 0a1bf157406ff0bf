"""The HumanML3D 263-d motion representation: its slices, normalisation and joint recovery.

Layout for J = 22 joints (``EricGuo5513/HumanML3D motion_representation.ipynb``):

=============  =====  ==========================================================================
slice          dims   content
=============  =====  ==========================================================================
``[0:1]``      1      root angular velocity about Y (per frame)
``[1:3]``      2      root linear velocity on XZ, in the root facing frame
``[3:4]``      1      root height Y
``[4:67]``     63     ric: joints 1..21 relative to the root's XZ, rotated to face +Z
``[67:193]``   126    6D local rotations of joints 1..21
``[193:259]``  66     velocities of all 22 joints, rotated by the root facing
``[259:263]``  4      foot contacts: left (7, 10) then right (8, 11)
=============  =====  ==========================================================================

:func:`recover_from_ric` is the dataset's procedure (same in ``text-to-motion`` and MDM
``motion_process.py``) written with the toolkit's kornia quaternion maths; quaternions are (w, x, y, z).
"""

from __future__ import annotations

import torch
from skeleton_mamba.tasks.motion.rotations import quaternion_to_matrix

__all__ = [
    "NUM_JOINTS",
    "FEATURE_DIM",
    "ROOT_ROT_VELOCITY",
    "ROOT_LINEAR_VELOCITY",
    "ROOT_HEIGHT",
    "RIC",
    "ROT6D",
    "LOCAL_VELOCITY",
    "FOOT_CONTACT",
    "FPS",
    "feature_dim",
    "normalize",
    "denormalize",
    "recover_root_rotation_position",
    "recover_from_ric",
]

NUM_JOINTS = 22
FPS = 20.0


def feature_dim(num_joints: int = NUM_JOINTS) -> int:
    """Feature size ``8 + (J - 1) * 9 + 3 J`` (263 for HumanML3D's 22 joints, 251 for KIT-ML's 21)."""
    return 8 + (num_joints - 1) * 9 + 3 * num_joints


FEATURE_DIM = feature_dim(NUM_JOINTS)
ROOT_ROT_VELOCITY = slice(0, 1)
ROOT_LINEAR_VELOCITY = slice(1, 3)
ROOT_HEIGHT = slice(3, 4)
RIC = slice(4, 4 + (NUM_JOINTS - 1) * 3)
ROT6D = slice(RIC.stop, RIC.stop + (NUM_JOINTS - 1) * 6)
LOCAL_VELOCITY = slice(ROT6D.stop, ROT6D.stop + NUM_JOINTS * 3)
FOOT_CONTACT = slice(LOCAL_VELOCITY.stop, LOCAL_VELOCITY.stop + 4)


def normalize(features: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """``(x - Mean) / Std`` over the last axis: (..., 263) -> (..., 263)."""
    return (features - mean) / std


def denormalize(features: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """``x * Std + Mean`` over the last axis, the inverse of :func:`normalize`."""
    return features * std + mean


def _rotate_by_inverse(quaternion: torch.Tensor, vectors: torch.Tensor) -> torch.Tensor:
    """Rotate vectors (..., 3) by the inverse of unit quaternions (..., 4) (w, x, y, z): ``R^T v``."""
    matrix = quaternion_to_matrix(quaternion)
    return torch.einsum("...ji,...j->...i", matrix, vectors)


def recover_root_rotation_position(features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Root facing quaternion and root position from de-normalised features.

    Args:
        features: (..., T, D) de-normalised features (D >= 4).

    Returns:
        ``(quaternion, position)``: (..., T, 4) root yaw ``(cos th_t, 0, sin th_t, 0)`` with
        ``th_t = sum_{s<t} f_s[0]``, and (..., T, 3) root positions (XZ integrated from the
        velocities rotated by the inverse yaw, Y the stored height).
    """
    rot_velocity = features[..., 0]
    angle = torch.zeros_like(rot_velocity)
    angle[..., 1:] = rot_velocity[..., :-1]
    angle = torch.cumsum(angle, dim=-1)
    zero = torch.zeros_like(angle)
    quaternion = torch.stack([torch.cos(angle), zero, torch.sin(angle), zero], dim=-1)

    velocity = torch.zeros(*features.shape[:-1], 3, dtype=features.dtype, device=features.device)
    velocity[..., 1:, 0] = features[..., :-1, 1]
    velocity[..., 1:, 2] = features[..., :-1, 2]
    position = torch.cumsum(_rotate_by_inverse(quaternion, velocity), dim=-2)
    position[..., 1] = features[..., 3]
    return quaternion, position


def recover_from_ric(features: torch.Tensor, num_joints: int = NUM_JOINTS) -> torch.Tensor:
    """Joint positions from de-normalised features (the dataset's ``recover_from_ric``).

    Args:
        features: (..., T, D) de-normalised HumanML3D features, ``D = feature_dim(num_joints)``.
        num_joints: J (22 for HumanML3D).

    Returns:
        (..., T, J, 3) y-up joint positions in metres; joint 0 is the root.
    """
    expected = feature_dim(num_joints)
    if features.shape[-1] != expected:
        raise ValueError(
            f"expected (..., T, {expected}) features for {num_joints} joints, got {tuple(features.shape)}"
        )
    quaternion, root = recover_root_rotation_position(features)
    ric = features[..., 4 : 4 + (num_joints - 1) * 3].unflatten(-1, (num_joints - 1, 3))
    joints = _rotate_by_inverse(quaternion.unsqueeze(-2).expand(*ric.shape[:-1], 4), ric)
    offset = torch.zeros_like(root)
    offset[..., 0] = root[..., 0]
    offset[..., 2] = root[..., 2]
    joints = joints + offset.unsqueeze(-2)
    return torch.cat([root.unsqueeze(-2), joints], dim=-2)
