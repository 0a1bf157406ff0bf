"""Ground contact quality of joint motions: foot skating and ground penetration (lower is better).

``foot_skating_ratio`` follows [GMD] (Karunratanakul et al. 2023, "foot skating ratio"): the share of
frame pairs in which a foot touches the ground (its toe joint below ``contact_height``, 5 cm, in both
frames) and slides horizontally faster than ``max_speed`` (0.5 m/s, GMD's 2.5 cm per frame at 20 fps),
taken over both feet. ``ground_penetration`` follows the "Penetrate" metric of [PhysDiff] (Yuan et al.
2023) on joints: the mean over frames of how far the lowest joint lies below the floor (metres, 0 when
above it). Both need the floor at height ``floor`` on the ``up_axis`` (the egodance data: y = 0).
"""

from __future__ import annotations

import torch

__all__ = ["TOE_JOINTS", "foot_skating_ratio", "ground_penetration"]

TOE_JOINTS = (10, 11)  # ltoes, rtoes in SMPL-24 and HumanML3D-22


def foot_skating_ratio(
    joints: torch.Tensor,
    fps: float,
    up_axis: int = 1,
    floor: float = 0.0,
    contact_height: float = 0.05,
    max_speed: float = 0.5,
    feet: tuple[int, ...] = TOE_JOINTS,
) -> torch.Tensor:
    """Share of (frame pair, foot) in ground contact that slide faster than ``max_speed`` m/s.

    Args:
        joints: (T, J, 3) positions in metres.
        fps: frame rate.

    Examples:
        Both toes on the floor (y up), the left one sliding 3 m/s at 30 fps:

        >>> import torch
        >>> joints = torch.zeros(5, 24, 3)
        >>> joints[:, 10, 0] = 0.1 * torch.arange(5.0)
        >>> float(foot_skating_ratio(joints, fps=30.0))
        0.5
    """
    if joints.ndim != 3 or joints.shape[0] < 2:
        raise ValueError(f"expected (T >= 2, J, 3) joint positions, got {tuple(joints.shape)}")
    p = joints[:, list(feet)].double()
    height = p[..., up_axis] - floor
    contact = (height[1:] < contact_height) & (height[:-1] < contact_height)  # (T-1, F)
    flat = [axis for axis in range(3) if axis != up_axis]
    speed = (p[1:, :, flat] - p[:-1, :, flat]).norm(dim=-1) * fps
    return ((speed > max_speed) & contact).double().mean()


def ground_penetration(joints: torch.Tensor, up_axis: int = 1, floor: float = 0.0) -> torch.Tensor:
    """Mean over frames of ``max(0, floor - lowest joint height)`` (metres) of (T, J, 3) positions.

    Examples:
        >>> import torch
        >>> joints = torch.zeros(3, 24, 3)
        >>> joints[:, 10, 1] = -0.02  # a toe 2 cm under the floor (y up)
        >>> round(float(ground_penetration(joints)), 4)
        0.02
    """
    if joints.ndim != 3:
        raise ValueError(f"expected (T, J, 3) joint positions, got {tuple(joints.shape)}")
    lowest = joints[..., up_axis].double().min(dim=-1).values
    return (floor - lowest).clamp(min=0).mean()
