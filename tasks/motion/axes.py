"""Up-axis conversions between the toolkit's y-up frame and z-up frames (EDGE, Blender, PFC).

y-up -> z-up is a rotation of +90 degrees about x: ``(x, y, z) -> (x, -z, y)``, so +y (up) becomes
+z and +z (the AIST++ forward direction) becomes -y. For SMPL motion the root orientation is
left-multiplied by the same rotation and the root translation rotated; rest offsets stay in the body
frame (Stanford-TML/EDGE ``dataset/dance_dataset.py``: root quaternion (w, x, y, z) =
(0.7071068, 0.7071068, 0, 0)).
"""

from __future__ import annotations

import torch

__all__ = [
    "Y_UP_TO_Z_UP",
    "y_up_to_z_up",
    "z_up_to_y_up",
    "root_rotation_y_up_to_z_up",
    "root_rotation_z_up_to_y_up",
]

# Rotation matrix of +90 degrees about x (acting on column vectors).
Y_UP_TO_Z_UP: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))


def _matrix(like: torch.Tensor) -> torch.Tensor:
    return torch.tensor(Y_UP_TO_Z_UP, dtype=like.dtype, device=like.device)


def y_up_to_z_up(points: torch.Tensor) -> torch.Tensor:
    """Points or vectors (..., 3) from y-up to z-up coordinates."""
    return points @ _matrix(points).T


def z_up_to_y_up(points: torch.Tensor) -> torch.Tensor:
    """Points or vectors (..., 3) from z-up to y-up coordinates (inverse of :func:`y_up_to_z_up`)."""
    return points @ _matrix(points)


def root_rotation_y_up_to_z_up(rotation: torch.Tensor) -> torch.Tensor:
    """Global root orientations (..., 3, 3) from y-up to z-up world frame (left-multiplication)."""
    return _matrix(rotation) @ rotation


def root_rotation_z_up_to_y_up(rotation: torch.Tensor) -> torch.Tensor:
    """Global root orientations (..., 3, 3) from z-up to y-up world frame."""
    return _matrix(rotation).T @ rotation
