"""Placing a motion window in a scene ([EgoMusic] supp. Sec. 5, step 2).

A placement is a rigid motion of the whole window: a heading ``yaw`` about the y (up) axis and a
translation. The window's mean root position (x, z) goes to a point drawn uniformly over the floor
triangles, and the height is chosen so that the lowest foot joint of the window (ankles and toes, all
frames) is :data:`~penetration.FOOT_RADIUS` above the floor, i.e. the bottom of the lowest foot capsule
touches the floor. With an SMPL mesh (``--smpl-model``) the lowest mesh vertex of the window touches
the floor instead (``lowest`` = its height, ``foot_radius`` = 0). Placed positions are
``p' = R_y(yaw) p + translation``; the placed SMPL motion has root orientation ``R_y(yaw) R_0`` and
root translation ``R_y(yaw) trans + translation``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from skeleton_mamba.tasks.egodance.builder.penetration import FOOT_JOINTS, FOOT_RADIUS
from skeleton_mamba.tasks.egodance.builder.scene import SceneMesh

__all__ = ["Placement", "yaw_matrix", "random_placement", "place_points"]


def yaw_matrix(yaw: float) -> np.ndarray:
    """(3, 3) rotation by ``yaw`` radians about +y (x -> -z for yaw = +90 degrees)."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass(frozen=True)
class Placement:
    """A rigid placement ``p' = R_y(yaw) p + translation`` (y-up scene coordinates, metres, radians)."""

    yaw: float
    translation: tuple[float, float, float]

    @property
    def rotation(self) -> np.ndarray:
        return yaw_matrix(self.yaw)

    def to_dict(self) -> dict:
        return asdict(self)


def place_points(points: np.ndarray, placement: Placement) -> np.ndarray:
    """Apply a placement to points (..., 3)."""
    return points @ placement.rotation.T + np.asarray(placement.translation)


def random_placement(
    joints: np.ndarray,
    scene: SceneMesh,
    rng: np.random.Generator,
    foot_radius: float = FOOT_RADIUS,
    lowest: float | None = None,
) -> Placement:
    """A random floor location and heading for a window with joints (T, 24, 3) (module docstring).

    Args:
        joints: (T, 24, 3) joints of the window (motion frame, y-up).
        scene: the scene; rng: the random generator.
        foot_radius: height of the lowest point above the floor.
        lowest: the window's lowest height (y) to put on the floor; default: its lowest foot joint.
            A yaw rotation keeps heights, so this is the same before and after the rotation.
    """
    yaw = float(rng.uniform(-np.pi, np.pi))
    rotated = joints @ yaw_matrix(yaw).T
    target = scene.sample_floor(1, rng)[0]
    centre = rotated[:, 0].mean(axis=0)
    lowest = rotated[:, FOOT_JOINTS, 1].min() if lowest is None else lowest
    translation = (
        float(target[0] - centre[0]),
        float(scene.floor_height + foot_radius - lowest),
        float(target[2] - centre[2]),
    )
    return Placement(yaw=yaw, translation=translation)
