"""SMPL-24 forward kinematics without the SMPL model file.

Joint order and parents are :data:`skeleton_mamba.skeletons.SMPL24`; the rest offsets (metres, y-up,
mean body shape) are the table of Stanford-TML/EDGE ``vis.py``.
Offset-table FK puts the pelvis at the root translation; the SMPL body model adds a shape-dependent
pelvis offset ``J_0(beta)`` and slightly different bone lengths, so positions are close to, not equal
to, those of the SMPL model (metrics computed from them are close, not identical).
"""

from __future__ import annotations

import torch

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.body.kinematics import forward_kinematics
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix

__all__ = [
    "SMPL_REST_OFFSETS",
    "smpl_rest_offsets",
    "smpl_forward_kinematics",
    "smpl_forward_kinematics_axis_angle",
]

# (24, 3) offset of each joint from its parent in the rest pose, metres, y-up (EDGE vis.py).
SMPL_REST_OFFSETS: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.0, 0.0),
    (0.05858135, -0.08228004, -0.01766408),
    (-0.06030973, -0.09051332, -0.01354254),
    (0.00443945, 0.12440352, -0.03838522),
    (0.04345142, -0.38646945, 0.008037),
    (-0.04325663, -0.38368791, -0.00484304),
    (0.00448844, 0.1379564, 0.02682033),
    (-0.01479032, -0.42687458, -0.037428),
    (0.01905555, -0.4200455, -0.03456167),
    (-0.00226458, 0.05603239, 0.00285505),
    (0.04105436, -0.06028581, 0.12204243),
    (-0.03483987, -0.06210566, 0.13032329),
    (-0.0133902, 0.21163553, -0.03346758),
    (0.07170245, 0.11399969, -0.01889817),
    (-0.08295366, 0.11247234, -0.02370739),
    (0.01011321, 0.08893734, 0.05040987),
    (0.12292141, 0.04520509, -0.019046),
    (-0.11322832, 0.04685326, -0.00847207),
    (0.2553319, -0.01564902, -0.02294649),
    (-0.26012748, -0.01436928, -0.03126873),
    (0.26570925, 0.01269811, -0.00737473),
    (-0.26910836, 0.00679372, -0.00602676),
    (0.08669055, -0.01063603, -0.01559429),
    (-0.0887537, -0.00865157, -0.01010708),
)


def smpl_rest_offsets(
    dtype: torch.dtype = torch.float32, device: torch.device | str | None = None
) -> torch.Tensor:
    """The rest offsets as a (24, 3) tensor."""
    return torch.tensor(SMPL_REST_OFFSETS, dtype=dtype, device=device)


def smpl_forward_kinematics(
    rotations: torch.Tensor,
    root_translation: torch.Tensor,
    offsets: torch.Tensor | None = None,
) -> torch.Tensor:
    """SMPL-24 joint positions from local rotation matrices.

    Args:
        rotations: (..., 24, 3, 3) local joint rotations (joint 0 = global root orientation).
        root_translation: (..., 3) pelvis position in metres (AIST++: ``smpl_trans / smpl_scaling``).
        offsets: (24, 3) or (..., 24, 3) rest offsets; default :data:`SMPL_REST_OFFSETS`.

    Returns:
        (..., 24, 3) joint positions in metres, in the frame of ``root_translation`` (y-up for AIST++).
    """
    if offsets is None:
        offsets = smpl_rest_offsets(rotations.dtype, rotations.device)
    positions, _ = forward_kinematics(rotations, root_translation, offsets, SMPL24.parents)
    return positions


def smpl_forward_kinematics_axis_angle(
    poses: torch.Tensor,
    root_translation: torch.Tensor,
    offsets: torch.Tensor | None = None,
) -> torch.Tensor:
    """:func:`smpl_forward_kinematics` taking axis-angle poses (..., 24, 3) or flat (..., 72)."""
    if poses.shape[-1] == 72:
        poses = poses.reshape(*poses.shape[:-1], 24, 3)
    if poses.shape[-2:] != (24, 3):
        raise ValueError(f"SMPL poses must be (..., 24, 3) or (..., 72) axis-angle, got {tuple(poses.shape)}")
    return smpl_forward_kinematics(axis_angle_to_matrix(poses), root_translation, offsets)
