"""The egocentric head camera ([EgoMusic] supp. Sec. 5: "the camera is positioned at the mesh index
located between the eyes, simulating a forward-facing egocentric perspective").

Without the SMPL mesh the eye midpoint is the head joint (15) plus an offset in the head joint's frame:
``eyes = p_15 + R_15 @ (0, up, forward)`` (SMPL's rest frame: +y up, +z forward, +x the body's left;
defaults 0.06 m up and 0.10 m forward, a rough estimate of where the eyes sit relative to the SMPL head
joint; both are options). The camera looks along the head's forward axis.

Conventions (OpenCV): camera axes x right, y down, z forward; ``rotation`` is camera-to-world
(its columns are the camera axes in world coordinates), ``position`` the optical centre in world
coordinates, so ``X_world = rotation @ X_cam + position``. Intrinsics ``K = [[f, 0, W/2], [0, f, H/2],
[0, 0, 1]]`` with ``f = (W/2) / tan(fov_x/2)``; pixel (u, v) has its centre at ``(u + 0.5, v + 0.5)``.
With the head frame above, ``rotation = R_15 @ diag(-1, -1, 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CameraTrajectory", "intrinsics", "head_camera", "pixel_rays", "HEAD_TO_CAMERA"]

HEAD_TO_CAMERA = np.diag(
    [-1.0, -1.0, 1.0]
)  # SMPL head frame (left, up, forward) -> OpenCV (right, down, fwd)


def intrinsics(width: int, height: int, fov_x_deg: float) -> np.ndarray:
    """(3, 3) pinhole intrinsics for a horizontal field of view in degrees."""
    if not 0 < fov_x_deg < 180:
        raise ValueError(f"horizontal field of view must be in (0, 180) degrees, got {fov_x_deg}")
    f = (width / 2) / np.tan(np.radians(fov_x_deg) / 2)
    return np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])


@dataclass
class CameraTrajectory:
    """Per-frame camera poses plus intrinsics.

    Attributes:
        positions: (T, 3) optical centres, world (scene) coordinates, metres.
        rotations: (T, 3, 3) camera-to-world rotations (OpenCV axes).
        K: (3, 3) intrinsics.
        width: image width in pixels.
        height: image height in pixels.
    """

    positions: np.ndarray
    rotations: np.ndarray
    K: np.ndarray
    width: int
    height: int

    def __len__(self) -> int:
        return len(self.positions)


def head_camera(
    head_positions: np.ndarray,
    head_rotations: np.ndarray,
    K: np.ndarray,
    width: int,
    height: int,
    forward_offset: float = 0.10,
    up_offset: float = 0.06,
) -> CameraTrajectory:
    """The eye camera of a motion from the head joint's world positions (T, 3) and rotations (T, 3, 3)."""
    offset = np.array([0.0, up_offset, forward_offset])
    positions = head_positions + head_rotations @ offset
    return CameraTrajectory(positions, head_rotations @ HEAD_TO_CAMERA, K, width, height)


def pixel_rays(K: np.ndarray, width: int, height: int) -> np.ndarray:
    """(H*W, 3) camera-frame ray directions with unit z (row-major pixel order), so the ray
    parameter of a hit is its z-depth."""
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    x = (u - K[0, 2]) / K[0, 0]
    y = (v - K[1, 2]) / K[1, 1]
    return np.stack([x, y, np.ones_like(x)], axis=-1).reshape(-1, 3)
