"""The EMM motion representation: per-joint tokens of rot6d + root position + foot contact at 30 fps.

EDGE's 151-d frame vector (EDGE ``dataset/dance_dataset.py``) is [4 foot contacts | 3 root position |
24 x 6 rot6d]; the backbone works on joint tokens, so each frame is packed as (24, C = 10):

=========  ==============================================================================
channels   content
=========  ==============================================================================
0-5        the joint's local rotation as 6D (toolkit convention: first two matrix columns)
6-8        the root position in metres, on joint 0 only (zeros elsewhere)
9          foot contact in {0, 1}, on joints 7, 8, 10, 11 (lankle, rankle, ltoes, rtoes) only
=========  ==============================================================================

Unused slots are zero in data and ignored by :data:`CHANNEL_MASK`-weighted losses and by decoding,
so the packing carries exactly EDGE's 151 numbers. Contacts follow EDGE: per-frame displacement of the
foot joint below 0.01 m at 30 fps (the last frame's displacement counts as 0).
"""

from __future__ import annotations

import torch

from skeleton_mamba.tasks.motion.body.rotations import (
    axis_angle_to_matrix,
    matrix_to_rotation_6d,
    rotation_6d_to_matrix,
)
from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics

__all__ = [
    "FPS",
    "NUM_JOINTS",
    "NUM_CHANNELS",
    "FOOT_JOINTS",
    "HEAD_JOINT",
    "ROT",
    "ROOT",
    "CONTACT",
    "channel_mask",
    "foot_contacts",
    "encode_motion",
    "decode_motion",
    "motion_joints",
]

FPS = 30
"""Motion and music frame rate of EgoAIST++ samples (what ``sm make-ego`` writes) and of EMM ([EgoMusic]): the
data modules' default, linked from them to the model, and the default of every function of this task that
takes a frame rate."""

NUM_JOINTS = 24
NUM_CHANNELS = 10
FOOT_JOINTS = (7, 8, 10, 11)
HEAD_JOINT = 15
ROT = slice(0, 6)
ROOT = slice(6, 9)
CONTACT = 9
CONTACT_THRESHOLD_M = 0.01


def channel_mask(
    dtype: torch.dtype = torch.float32, device: torch.device | str | None = None
) -> torch.Tensor:
    """(24, 10) with 1 on the slots that carry data (6 x 24 + 3 + 4 = 151 ones)."""
    mask = torch.zeros(NUM_JOINTS, NUM_CHANNELS, dtype=dtype, device=device)
    mask[:, ROT] = 1
    mask[0, ROOT] = 1
    mask[list(FOOT_JOINTS), CONTACT] = 1
    return mask


def foot_contacts(joints: torch.Tensor, threshold: float = CONTACT_THRESHOLD_M) -> torch.Tensor:
    """(..., T, 24, 3) joint positions -> (..., T, 4) float contacts of joints 7, 8, 10, 11 (EDGE rule)."""
    feet = joints[..., list(FOOT_JOINTS), :]
    disp = (feet[..., 1:, :, :] - feet[..., :-1, :, :]).norm(dim=-1)
    disp = torch.cat([disp, torch.zeros_like(disp[..., :1, :])], dim=-2)
    return (disp < threshold).to(joints.dtype)


def encode_motion(poses: torch.Tensor, root: torch.Tensor) -> torch.Tensor:
    """SMPL axis-angle poses (..., T, 24, 3) and root positions (..., T, 3) in metres -> (..., T, 24, 10)."""
    if poses.shape[-2:] != (NUM_JOINTS, 3) or root.shape[-1] != 3 or poses.shape[:-2] != root.shape[:-1]:
        raise ValueError(
            f"expected poses (..., T, 24, 3) and root (..., T, 3), got {tuple(poses.shape)}, "
            f"{tuple(root.shape)}"
        )
    rotations = axis_angle_to_matrix(poses)
    joints = smpl_forward_kinematics(rotations, root)
    x = poses.new_zeros(*poses.shape[:-1], NUM_CHANNELS)
    x[..., ROT] = matrix_to_rotation_6d(rotations)
    x[..., 0, ROOT] = root
    x[..., list(FOOT_JOINTS), CONTACT] = foot_contacts(joints)
    return x


def decode_motion(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(..., T, 24, 10) -> rotations (..., T, 24, 3, 3), root (..., T, 3), contacts (..., T, 4)."""
    if x.shape[-2:] != (NUM_JOINTS, NUM_CHANNELS):
        raise ValueError(f"expected (..., T, 24, 10) motion tokens, got {tuple(x.shape)}")
    return rotation_6d_to_matrix(x[..., ROT]), x[..., 0, ROOT], x[..., list(FOOT_JOINTS), CONTACT]


def motion_joints(x: torch.Tensor) -> torch.Tensor:
    """FK: (..., T, 24, 10) motion tokens -> (..., T, 24, 3) joint positions in metres (differentiable)."""
    rotations, root, _ = decode_motion(x)
    return smpl_forward_kinematics(rotations, root)
