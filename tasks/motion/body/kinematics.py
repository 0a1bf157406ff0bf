"""Forward kinematics of a joint tree from local rotations and rest offsets (batched, differentiable).

For every joint ``j`` with parent ``p`` (parents visited before children)::

    R_world[j] = R_world[p] @ R_local[j]
    pos[j]     = pos[p] + R_world[p] @ offset[j]

and a root has ``R_world[root] = R_local[root]``, ``pos[root] = root_translation``. This is the
algorithm of Stanford-TML/EDGE ``vis.py`` (``SMPLSkeleton.forward``) written with rotation matrices;
SMPL, BVH and any other offset-table skeleton use it.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

__all__ = ["forward_kinematics"]


def forward_kinematics(
    local_rotations: torch.Tensor,
    root_translation: torch.Tensor,
    offsets: torch.Tensor,
    parents: Sequence[int],
    order: Sequence[int] | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """World joint positions and rotations of a joint tree.

    Args:
        local_rotations: (..., J, 3, 3) rotation of each joint relative to its parent's frame.
        root_translation: (..., 3) world position of the root joint(s).
        offsets: (J, 3) or (..., J, 3) rest offset of each joint from its parent, in the parent's
            frame (the root's own offset is ignored: its position is ``root_translation``).
        parents: J parent indices, ``-1`` for a root.
        order: joint visiting order with parents first (e.g. ``Skeleton.topological_order``); by
            default the index order, which requires ``parents[j] < j`` (true for SMPL and BVH files).

    Returns:
        ``(positions, world_rotations)`` of shapes (..., J, 3) and (..., J, 3, 3).
    """
    num_joints = len(parents)
    if local_rotations.shape[-3:] != (num_joints, 3, 3):
        raise ValueError(
            f"local_rotations must be (..., {num_joints}, 3, 3) for {num_joints} parents, "
            f"got {tuple(local_rotations.shape)}"
        )
    if root_translation.shape[-1] != 3:
        raise ValueError(f"root_translation must be (..., 3), got {tuple(root_translation.shape)}")
    if offsets.shape[-2:] != (num_joints, 3):
        raise ValueError(f"offsets must be (..., {num_joints}, 3), got {tuple(offsets.shape)}")
    # Broadcast on the meta device: torch.broadcast_shapes imports torch's symbolic-shape machinery
    # (about a second) on first use.
    shapes = (local_rotations.shape[:-3], root_translation.shape[:-1], offsets.shape[:-2])
    batch = torch.broadcast_tensors(*(torch.empty(s, device="meta") for s in shapes))[0].shape
    offsets = offsets.to(local_rotations)
    root_translation = root_translation.to(local_rotations)

    positions: list[torch.Tensor | None] = [None] * num_joints
    rotations: list[torch.Tensor | None] = [None] * num_joints
    if order is None:
        if any(p >= j for j, p in enumerate(parents)):
            raise ValueError(f"parents are not sorted (parent after child), pass `order`: {list(parents)}")
        order = range(num_joints)
    for j in order:
        p = parents[j]
        if p < 0:
            rotations[j] = local_rotations[..., j, :, :].expand(*batch, 3, 3)
            positions[j] = root_translation.expand(*batch, 3)
        else:
            rotations[j] = rotations[p] @ local_rotations[..., j, :, :]
            positions[j] = positions[p] + (rotations[p] @ offsets[..., j, :, None])[..., 0]
    return torch.stack(positions, dim=-2), torch.stack(rotations, dim=-3)
