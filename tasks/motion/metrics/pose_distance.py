"""Pose plausibility: how far each generated pose lies from the nearest pose of a motion set.

Poses are compared *root-aligned*: each frame's joints are moved so the root (joint 0) is at the origin
and turned about the vertical axis so the hip line (left hip 1 -> right hip 2, SMPL-24 and HumanML3D-22
alike) points along +x (:func:`canonical_poses`). The distance of two poses is their MPJPE, the mean
over joints of the Euclidean distance in metres; :func:`nearest_pose_distance` averages, over the frames of
a motion, the distance to the nearest frame of a reference set (e.g. the training motions). A motion made
of training poses scores 0; a tangle of limbs scores tens of centimetres.
"""

from __future__ import annotations

import torch

__all__ = ["canonical_poses", "mpjpe", "nearest_pose_distance", "pose_set_distance"]

LEFT_HIP, RIGHT_HIP = 1, 2


def canonical_poses(joints: torch.Tensor, up_axis: int = 1) -> torch.Tensor:
    """(..., J, 3) joint positions -> the same poses with the root at 0 and the hip line along +x.

    Examples:
        A root and two hips, y up, the hip line along -z: turned to +x.

        >>> import torch
        >>> joints = torch.tensor([[1.0, 0.0, 1.0], [1.0, 0.0, 2.0], [1.0, 0.0, 0.0]])
        >>> (canonical_poses(joints).round(decimals=4) + 0.0).tolist()
        [[0.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    """
    if joints.shape[-1] != 3 or joints.shape[-2] < 3:
        raise ValueError(f"expected (..., J >= 3, 3) joint positions, got {tuple(joints.shape)}")
    p = joints - joints[..., :1, :]
    a, b = [axis for axis in range(3) if axis != up_axis]
    across = p[..., RIGHT_HIP, :] - p[..., LEFT_HIP, :]
    theta = torch.atan2(across[..., b], across[..., a])[..., None]  # (..., 1)
    cos, sin = torch.cos(theta), torch.sin(theta)
    out = p.clone()
    out[..., a] = cos * p[..., a] + sin * p[..., b]
    out[..., b] = -sin * p[..., a] + cos * p[..., b]
    return out


def mpjpe(pred: torch.Tensor, true: torch.Tensor) -> torch.Tensor:
    """Mean per-joint position error (metres) over every frame and joint of (..., J, 3) positions.

    Examples:
        >>> import torch
        >>> true = torch.zeros(2, 24, 3)
        >>> round(float(mpjpe(true + torch.tensor([0.03, 0.04, 0.0]), true)), 4)  # every joint 5 cm off
        0.05
    """
    if pred.shape != true.shape:
        raise ValueError(f"pred {tuple(pred.shape)} and true {tuple(true.shape)} differ in shape")
    return (pred - true).norm(dim=-1).mean()


def nearest_pose_distance(motion: torch.Tensor, reference: torch.Tensor, up_axis: int = 1) -> torch.Tensor:
    """Mean over the frames of ``motion`` (T, J, 3) of the root-aligned MPJPE to the nearest frame of
    ``reference`` (N, J, 3) (metres).

    Examples:
        Poses of the reference, moved elsewhere and turned about the vertical axis, are 0 m from it:

        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> reference = torch.randn(5, 24, 3)
        >>> turn = torch.tensor([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # 90 degrees about y
        >>> motion = reference[[3, 1]] @ turn.T + torch.tensor([2.0, 0.0, 0.0])
        >>> round(float(nearest_pose_distance(motion, reference)), 6)
        0.0
    """
    if motion.ndim != 3 or reference.ndim != 3 or motion.shape[1:] != reference.shape[1:]:
        raise ValueError(
            f"expected motion (T, J, 3) and reference (N, J, 3) with the same joints, got "
            f"{tuple(motion.shape)} and {tuple(reference.shape)}"
        )
    q = canonical_poses(motion.double(), up_axis)
    r = canonical_poses(reference.double(), up_axis)
    chunk = max(1, 2**21 // r.numel())  # frames per step: about 16 MiB of differences
    nearest = []
    for start in range(0, q.shape[0], chunk):
        d = (q[start : start + chunk, None] - r[None]).norm(dim=-1).mean(-1)  # (t, N)
        nearest.append(d.min(dim=1).values)
    return torch.cat(nearest).mean()


def pose_set_distance(a: torch.Tensor, b: torch.Tensor, up_axis: int = 1) -> torch.Tensor:
    """Symmetric :func:`nearest_pose_distance` of two motions (T_a, J, 3), (T_b, J, 3): how far apart the
    poses they visit are, whatever their timing (metres).

    Examples:
        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> a = torch.randn(5, 24, 3)
        >>> round(float(pose_set_distance(a, a[[4, 2, 0, 1, 3]])), 6), bool(pose_set_distance(a, a[:2]) > 0)
        (0.0, True)
    """
    return 0.5 * (nearest_pose_distance(a, b, up_axis) + nearest_pose_distance(b, a, up_axis))
