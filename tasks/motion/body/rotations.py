"""Rotation conversions: axis-angle, quaternion (w, x, y, z), rotation matrix, 6D and Euler angles.

Axis-angle, quaternion and matrix conversions are kornia's (batched over any leading shape,
differentiable). The 6D representation ([Rot6D]) has no kornia helper and is the only formula written
here: the first two *columns* of the rotation matrix, mapped back with Gram-Schmidt. pytorch3d and EDGE
store the first two *rows* instead; ``matrix_to_rotation_6d(R.transpose(-1, -2))`` gives theirs.

Euler angles follow the BVH convention: ``order`` names the axes in the order of the channels, and
the matrix is the product of the elementary rotations in that order (intrinsic rotations),
``euler_to_matrix(a, "ZXY") = Rz(a0) @ Rx(a1) @ Ry(a2)`` (scipy ``Rotation.from_euler("ZXY", a)``).
Each elementary rotation is kornia's axis-angle conversion about the unit axis.

Conventions: radians; rotation matrices act on column vectors; quaternions are (w, x, y, z).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from kornia.geometry import conversions as kc

__all__ = [
    "axis_angle_to_matrix",
    "matrix_to_axis_angle",
    "axis_angle_to_quaternion",
    "quaternion_to_axis_angle",
    "quaternion_to_matrix",
    "matrix_to_quaternion",
    "matrix_to_rotation_6d",
    "rotation_6d_to_matrix",
    "euler_to_matrix",
    "matrix_to_euler",
]

_AXES = {"X": 0, "Y": 1, "Z": 2}


def axis_angle_to_matrix(axis_angle: torch.Tensor) -> torch.Tensor:
    """Rotation vectors (..., 3) (axis times angle in radians) -> rotation matrices (..., 3, 3)."""
    return kc.axis_angle_to_rotation_matrix(axis_angle)


def matrix_to_axis_angle(matrix: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) -> rotation vectors (..., 3) with angle in [0, pi]."""
    return kc.rotation_matrix_to_axis_angle(matrix)


def axis_angle_to_quaternion(axis_angle: torch.Tensor) -> torch.Tensor:
    """Rotation vectors (..., 3) -> unit quaternions (..., 4) as (w, x, y, z)."""
    return kc.axis_angle_to_quaternion(axis_angle)


def quaternion_to_axis_angle(quaternion: torch.Tensor) -> torch.Tensor:
    """Quaternions (..., 4) as (w, x, y, z) -> rotation vectors (..., 3)."""
    return kc.quaternion_to_axis_angle(quaternion)


def quaternion_to_matrix(quaternion: torch.Tensor) -> torch.Tensor:
    """Quaternions (..., 4) as (w, x, y, z) -> rotation matrices (..., 3, 3) (normalises first)."""
    return kc.quaternion_to_rotation_matrix(kc.normalize_quaternion(quaternion))


def matrix_to_quaternion(matrix: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4) as (w, x, y, z)."""
    return kc.rotation_matrix_to_quaternion(matrix)


def matrix_to_rotation_6d(matrix: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) -> 6D (..., 6): first column then second column (Zhou et al.)."""
    return torch.cat([matrix[..., :, 0], matrix[..., :, 1]], dim=-1)


def rotation_6d_to_matrix(rot6d: torch.Tensor) -> torch.Tensor:
    """6D (..., 6) -> rotation matrices (..., 3, 3) by Gram-Schmidt (Zhou et al., Eq. 16).

    ``b1 = a1 / |a1|``, ``b2 = normalise(a2 - (b1 . a2) b1)``, ``b3 = b1 x b2``; the columns of the
    result are ``b1, b2, b3``. Any 6-vector with non-parallel halves maps to a proper rotation.
    """
    a1, a2 = rot6d[..., :3], rot6d[..., 3:]
    b1 = F.normalize(a1, dim=-1)
    b2 = F.normalize(a2 - (b1 * a2).sum(-1, keepdim=True) * b1, dim=-1)
    b3 = torch.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], dim=-1)


def _check_order(order: str) -> str:
    order = order.upper()
    if len(order) != 3 or any(a not in _AXES for a in order):
        raise ValueError(f"Euler order must be three of X, Y, Z (e.g. 'ZXY'), got {order!r}")
    return order


def euler_to_matrix(angles: torch.Tensor, order: str) -> torch.Tensor:
    """Intrinsic Euler angles (..., n) in radians -> rotation matrices (..., 3, 3).

    Args:
        angles: one angle per axis of ``order``, in that order: (..., len(order)).
        order: axis names in channel order, e.g. ``"ZXY"``; the result is
            ``R_{order[0]}(angles[..., 0]) @ R_{order[1]}(angles[..., 1]) @ R_{order[2]}(angles[..., 2])``.
            Repeated axes (``"ZXZ"``) are allowed, and so are one or two axes (BVH joints with fewer
            rotation channels).
    """
    order = order.upper()
    if not 1 <= len(order) <= 3 or any(a not in _AXES for a in order):
        raise ValueError(f"Euler order must be one to three of X, Y, Z (e.g. 'ZXY'), got {order!r}")
    if angles.shape[-1] != len(order):
        raise ValueError(f"expected angles (..., {len(order)}) for order {order}, got {tuple(angles.shape)}")
    result = None
    for i, axis in enumerate(order):
        unit = torch.zeros(3, dtype=angles.dtype, device=angles.device)
        unit[_AXES[axis]] = 1.0
        r = axis_angle_to_matrix(angles[..., i : i + 1] * unit)
        result = r if result is None else result @ r
    return result


def matrix_to_euler(matrix: torch.Tensor | np.ndarray, order: str) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> intrinsic Euler angles (..., 3) in radians (scipy, no gradient).

    The inverse of :func:`euler_to_matrix` for the same ``order`` (used when writing BVH files).
    """
    from scipy.spatial.transform import Rotation  # lazy: scipy only for this conversion

    order = _check_order(order)
    if isinstance(matrix, torch.Tensor):
        matrix = matrix.detach().cpu().double().numpy()
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"expected matrices of shape (..., 3, 3), got {m.shape}")
    flat = m.reshape(-1, 3, 3)
    if flat.shape[0] == 0:
        return np.zeros((*m.shape[:-2], 3))
    return Rotation.from_matrix(flat).as_euler(order).reshape(*m.shape[:-2], 3)
