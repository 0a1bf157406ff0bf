"""A character's own mesh rendered to mp4 (with music) or GIF: ``sm render`` of a skinned ``.glb`` / ``.vrm``
(``sm retarget``'s output).

Each frame poses the mesh by linear blend skinning (:mod:`.character_mesh`) and draws its triangles with the
camera, floor grid and time stamp of the skeleton renderer (:mod:`.skeleton`: the camera fitted to the skin
joints over the whole clip): painter's order (farthest first), each triangle filled in the character's
colour shaded by the angle between its normal and a light from the camera's upper left (both sides lit, as
glTF's double-sided materials), the shadow the mesh casts straight down drawn first on the floor.
"""

from __future__ import annotations

from collections.abc import Iterator
from os import PathLike
from pathlib import Path

import cv2
import numpy as np

from skeleton_mamba.tasks.motion.render.character_mesh import CharacterMesh
from skeleton_mamba.tasks.motion.render.skeleton import (
    RenderStyle,
    _clip_size,
    _fixed,
    _floor_frames,
    _time_label,
    fit_cameras,
    write_video,
)

__all__ = ["mesh_frames", "render_character"]

COLOUR = np.array([150.0, 160.0, 190.0])  # RGB of the lit character
AMBIENT = 0.35
LIGHT = np.array([-0.4, 0.6, -0.7]) / np.linalg.norm([-0.4, 0.6, -0.7])  # camera axes: from the upper left


def mesh_frames(
    mesh: CharacterMesh, style: RenderStyle | None = None, title: str | None = None
) -> Iterator[np.ndarray]:
    """Yield one (H, W, 3) uint8 RGB image per frame of ``mesh``'s animation (module docstring)."""
    style = style or RenderStyle()
    joints = mesh.joint_positions()
    cameras = fit_cameras(joints, [-1] * joints.shape[1], mesh.fps, style)
    near, floor = 0.05 * _clip_size(joints), joints[..., 1].min()
    tri = mesh.triangles
    for t, (image, camera) in enumerate(_floor_frames(cameras, joints, style)):
        world = mesh.posed(t)
        shadow = world.copy()
        shadow[:, 1] = floor
        cam_shadow = camera.to_camera(shadow)
        if (cam_shadow[:, 2] > near).all():
            hull = cv2.convexHull(_fixed(camera.pixels(cam_shadow)).reshape(-1, 1, 2))
            cv2.fillConvexPoly(image, hull, style.shadow, cv2.LINE_AA, 4)
        cam = camera.to_camera(world)
        corners = cam[tri]  # (F, 3, 3)
        visible = (corners[..., 2] > near).all(1)
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        shade = AMBIENT + (1 - AMBIENT) * np.abs(normal @ LIGHT)
        colours = np.clip(COLOUR[None] * shade[:, None], 0, 255).astype(int)
        pixels = _fixed(camera.pixels(cam))[tri]  # (F, 3, 2)
        for f in np.argsort(-corners[..., 2].mean(1)):
            if visible[f]:
                cv2.fillConvexPoly(image, pixels[f], colours[f].tolist(), cv2.LINE_AA, 4)
        _time_label(image, t / mesh.fps, title)
        yield image


def render_character(
    mesh: CharacterMesh,
    out: str | PathLike[str],
    music: str | PathLike[str] | None = None,
    style: RenderStyle | None = None,
    title: str | None = None,
    progress: bool = True,
) -> Path:
    """Render ``mesh`` (every frame of its animation, at its frame rate) to ``out`` (``.mp4`` or ``.gif``)."""
    style = style or RenderStyle()
    frames = lambda: mesh_frames(mesh, style, title)  # noqa: E731
    return write_video(frames, mesh.num_frames, out, mesh.fps, music, style, progress)
