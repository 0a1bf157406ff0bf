"""Resampling motion between frame rates: slerp for rotations, linear interpolation for positions.

Frame ``k`` of the output lies at time ``k / dst_fps``; the output covers the input's duration
``(T - 1) / src_fps`` and has ``floor((T - 1) * dst_fps / src_fps) + 1`` frames. When ``src_fps`` is
a multiple of ``dst_fps`` the output is exactly every ``src_fps / dst_fps``-th input frame (AIST++
60 -> 30 fps as in EDGE); in between frames, rotations are slerped along the shorter arc (kornia
``Quaternion.slerp``) and translations interpolated linearly.
"""

from __future__ import annotations

import math

import torch
from kornia.geometry.quaternion import Quaternion

from skeleton_mamba.tasks.motion.body.rotations import (
    axis_angle_to_matrix,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    quaternion_to_matrix,
)

__all__ = ["resample_times", "resample_linear", "resample_rotations", "resample_smpl"]


def resample_times(num_frames: int, src_fps: float, dst_fps: float) -> torch.Tensor:
    """Fractional input-frame positions (T',) of the output frames (float64)."""
    if src_fps <= 0 or dst_fps <= 0:
        raise ValueError(f"frame rates must be positive, got src_fps={src_fps}, dst_fps={dst_fps}")
    if num_frames < 1:
        raise ValueError("cannot resample an empty motion")
    ratio = src_fps / dst_fps
    # A small tolerance keeps the last frame when (T - 1) * dst / src is an integer up to rounding.
    count = math.floor((num_frames - 1) / ratio + 1e-9) + 1
    return torch.arange(count, dtype=torch.float64) * ratio


def _neighbours(
    num_frames: int, src_fps: float, dst_fps: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    pos = resample_times(num_frames, src_fps, dst_fps)
    i0 = pos.floor().long().clamp(max=num_frames - 1)
    frac = pos - i0
    # Snap fractions that are integers up to float error so that 60 -> 30 takes frames exactly.
    frac = torch.where(frac.abs() < 1e-9, torch.zeros_like(frac), frac)
    i1 = (i0 + 1).clamp(max=num_frames - 1)
    return i0, i1, frac


def resample_linear(values: torch.Tensor, src_fps: float, dst_fps: float) -> torch.Tensor:
    """Linear interpolation along the first (time) axis: (T, ...) -> (T', ...)."""
    i0, i1, frac = _neighbours(values.shape[0], src_fps, dst_fps)
    w = frac.to(values.dtype).reshape(-1, *([1] * (values.dim() - 1)))
    return values[i0] * (1 - w) + values[i1] * w


def resample_rotations(rotations: torch.Tensor, src_fps: float, dst_fps: float) -> torch.Tensor:
    """Slerp rotation matrices along the first (time) axis: (T, ..., 3, 3) -> (T', ..., 3, 3)."""
    if rotations.shape[-2:] != (3, 3):
        raise ValueError(f"expected rotation matrices (T, ..., 3, 3), got {tuple(rotations.shape)}")
    i0, i1, frac = _neighbours(rotations.shape[0], src_fps, dst_fps)
    q = matrix_to_quaternion(rotations)
    q0, q1 = q[i0], q[i1]
    t = frac.to(q.dtype).reshape(-1, *([1] * (q.dim() - 2))).expand(q0.shape[:-1])
    flat = q0.reshape(-1, 4)
    out = Quaternion(flat).slerp(Quaternion(q1.reshape(-1, 4)), t.reshape(-1)).data
    result = quaternion_to_matrix(out.reshape(q0.shape))
    # Frames that coincide with an input frame are copied exactly (no conversion round-off).
    exact = frac == 0
    result[exact] = rotations[i0[exact]]
    return result


def resample_smpl(
    poses: torch.Tensor, translation: torch.Tensor, src_fps: float, dst_fps: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Resample SMPL motion: axis-angle poses (T, 24, 3) by slerp, translation (T, 3) linearly."""
    if poses.shape[0] != translation.shape[0]:
        raise ValueError(f"poses have {poses.shape[0]} frames but translation has {translation.shape[0]}")
    rotations = resample_rotations(axis_angle_to_matrix(poses), src_fps, dst_fps)
    i0, _, frac = _neighbours(poses.shape[0], src_fps, dst_fps)
    out_poses = matrix_to_axis_angle(rotations)
    exact = frac == 0
    out_poses[exact] = poses[i0[exact]]
    return out_poses, resample_linear(translation, src_fps, dst_fps)
