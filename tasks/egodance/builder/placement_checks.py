"""What the builder checks before it writes a placed window: feet over the floor, a view that sees the scene.

A placement (:mod:`.placement`) puts the window's mean root over a random floor point; a dance that sways
or travels can still leave the floor (a dancer at the floor's edge of an open scene, stepping over the
void), and a camera at the floor's edge facing outwards sees nothing: an all-black video. So a candidate
placement is also rejected (and another drawn) when

- :func:`feet_off_floor`: a foot joint (ankles and toes, every ``stride``-th frame) is not above a floor
  triangle: a ray cast straight down from just above the foot must first meet one of the scene's floor
  faces (:attr:`~.scene.SceneMesh.floor_faces`);
- :func:`view_hit_share`: fewer than ``min_view_hits`` (default :data:`MIN_VIEW_HITS`) of the first
  frame's camera rays hit any geometry.

Both are counted per window (``rejections`` of the build's summary) with the penetration rejections.
"""

from __future__ import annotations

import numpy as np

from skeleton_mamba.tasks.egodance.builder.camera import CameraTrajectory
from skeleton_mamba.tasks.egodance.builder.config import MIN_VIEW_HITS  # torch-free, for sm make-ego --help
from skeleton_mamba.tasks.egodance.builder.penetration import FOOT_JOINTS
from skeleton_mamba.tasks.egodance.builder.raycast import Renderer
from skeleton_mamba.tasks.egodance.builder.scene import SceneMesh

__all__ = ["MIN_VIEW_HITS", "REJECTIONS", "feet_off_floor", "view_hit_share"]

RAY_START_M = 0.05  # the downward rays start this far above each foot joint
REJECTIONS = ("penetration", "feet", "view")  # why a candidate placement was rejected


def feet_off_floor(scene: SceneMesh, joints: np.ndarray, stride: int = 1) -> int:
    """How many (frame, foot joint) of placed ``joints`` (T, 24, 3) (every ``stride``-th frame) are not
    above the floor: the first hit of a ray straight down from :data:`RAY_START_M` above is no floor face."""
    feet = joints[::stride][:, FOOT_JOINTS].reshape(-1, 3)
    origins = feet + np.array([0.0, RAY_START_M, 0.0])
    down = np.broadcast_to(np.array([0.0, -1.0, 0.0]), origins.shape)
    hits = scene.caster.first_hits(origins, down)
    return int((~np.isin(hits.tri, scene.floor_faces)).sum())


def view_hit_share(scene: SceneMesh, camera: CameraTrajectory) -> float:
    """The share of the first frame's pixels whose ray hits geometry (depth > 0)."""
    renderer = Renderer(scene, camera.K, camera.width, camera.height)
    _, depth = renderer.render(camera.positions[0], camera.rotations[0])
    return float((depth > 0).mean())
