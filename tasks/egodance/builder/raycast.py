"""Egocentric RGB + depth rendering by ray casting (embree through ``embreex`` when installed).

One ray per pixel centre (:func:`~camera.pixel_rays`); the first triangle hit gives

* depth: the z-depth of the hit in the camera frame (distance along the optical axis, metres), 0 where the
  ray hits nothing;
* RGB: the scene's vertex colours interpolated barycentrically at the hit, times a headlight shading
  ``ambient + (1 - ambient) * |n . v|`` (n the triangle normal, v the unit ray direction), the background
  colour where nothing is hit.

Speed: a :class:`Renderer` is built once per
scene and camera intrinsics and reused for every frame. It keeps the camera-frame ray directions (unit z,
so the hit parameter IS the z-depth) and their norms, and one float32 row per triangle (unit normal, the
colour of corner a and the colour differences b - a, c - a, in 0-255 units). A frame is then one rotation
of the directions, one embree call returning triangle, distance and barycentric coordinates
(:class:`~.ray_caster.RayCaster`), one row gather and a few float32 vector operations.
"""

from __future__ import annotations

import numpy as np

from skeleton_mamba.tasks.egodance.builder.camera import CameraTrajectory, pixel_rays
from skeleton_mamba.tasks.egodance.builder.scene import SceneMesh

__all__ = ["Renderer", "face_table", "render_view", "render_trajectory"]


def face_table(scene: SceneMesh) -> np.ndarray:
    """(F, 12) float32 per-triangle shading rows: unit normal, colour of corner a, colour b - a, colour c - a.

    Colours are the scene's vertex colours in 0-255 units, so ``a + u (b - a) + v (c - a)`` is the
    barycentric interpolation at the hit ``(1 - u - v) a + u b + v c``.
    """
    mesh = scene.mesh
    corners = scene.vertex_colors[np.asarray(mesh.faces)] * 255.0  # (F, 3 corners, 3 rgb)
    return np.concatenate(
        [
            np.asarray(mesh.face_normals, dtype=np.float64),
            corners[:, 0],
            corners[:, 1] - corners[:, 0],
            corners[:, 2] - corners[:, 0],
        ],
        axis=1,
    ).astype(np.float32)


class Renderer:
    """Renders views of one scene with one set of intrinsics (module docstring).

    Args:
        scene: the y-up scene.
        K: (3, 3) intrinsics; width, height: image size in pixels.
        ambient: the unlit fraction of the shading.
        background: RGB where no surface is hit.
    """

    def __init__(
        self,
        scene: SceneMesh,
        K: np.ndarray,
        width: int,
        height: int,
        ambient: float = 0.3,
        background: tuple[int, int, int] = (0, 0, 0),
    ) -> None:
        self.scene, self.width, self.height = scene, width, height
        self.caster = scene.caster
        rays = pixel_rays(K, width, height)  # (H*W, 3), z = 1
        # channel-first (3, N) / (12, F) layouts: the per-pixel arithmetic runs on contiguous rows
        self.rays_t = np.ascontiguousarray(rays.T, dtype=np.float32)
        self.inv_norm = (1.0 / np.linalg.norm(rays, axis=1)).astype(np.float32)  # rotation-invariant
        self.table_t = np.ascontiguousarray(face_table(scene).T)
        self.ambient = np.float32(ambient)
        self.background = np.asarray(background, dtype=np.uint8)

    def render(self, position: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One view from ``position`` (3,) with camera-to-world ``rotation`` (3, 3) (OpenCV axes).

        Returns:
            ``(rgb, depth)``: (H, W, 3) uint8 and (H, W) float32 metres.
        """
        dirs = np.asarray(rotation, dtype=np.float32) @ self.rays_t  # (3, N) world, unit optical z
        hits = self.caster.first_hits(np.asarray(position, dtype=np.float64), dirs.T)
        miss = hits.tri < 0
        row = np.take(self.table_t, np.maximum(hits.tri, 0), axis=1)  # (12, N)
        cos = np.abs(row[0] * dirs[0] + row[1] * dirs[1] + row[2] * dirs[2]) * self.inv_norm
        shade = self.ambient + (1.0 - self.ambient) * cos
        color = row[3:6] + hits.u * row[6:9] + hits.v * row[9:12]  # (3, N), 0-255
        color *= shade
        color += 0.5
        np.clip(color, 0.0, 255.0, out=color)
        rgb = np.empty((self.height * self.width, 3), dtype=np.uint8)
        rgb.T[...] = color  # truncation of x + 0.5: rounding
        depth = hits.t.astype(np.float32, copy=True)  # the ray parameter of unit-z rays is the z-depth
        if miss.any():
            rgb[miss] = self.background
            depth[miss] = 0.0
        return rgb.reshape(self.height, self.width, 3), depth.reshape(self.height, self.width)

    def render_trajectory(self, camera: CameraTrajectory) -> tuple[np.ndarray, np.ndarray]:
        """Every frame of a trajectory: (T, H, W, 3) uint8 RGB and (T, H, W) float32 depth."""
        rgb = np.empty((len(camera), self.height, self.width, 3), dtype=np.uint8)
        depth = np.empty((len(camera), self.height, self.width), dtype=np.float32)
        for i, (p, r) in enumerate(zip(camera.positions, camera.rotations)):
            rgb[i], depth[i] = self.render(p, r)
        return rgb, depth


def render_view(
    scene: SceneMesh,
    position: np.ndarray,
    rotation: np.ndarray,
    K: np.ndarray,
    width: int,
    height: int,
    ambient: float = 0.3,
    background: tuple[int, int, int] = (0, 0, 0),
) -> tuple[np.ndarray, np.ndarray]:
    """Render one view (a one-off :class:`Renderer`; build a Renderer to render many).

    Args:
        scene: the y-up scene.
        position: (3,) camera centre; rotation: (3, 3) camera-to-world (OpenCV axes).
        K: (3, 3) intrinsics; width, height: image size in pixels.
        ambient: the unlit fraction of the shading.
        background: RGB where no surface is hit.

    Returns:
        ``(rgb, depth)``: (H, W, 3) uint8 and (H, W) float32 metres.
    """
    return Renderer(scene, K, width, height, ambient, background).render(position, rotation)


def render_trajectory(
    scene: SceneMesh, camera: CameraTrajectory, ambient: float = 0.3
) -> tuple[np.ndarray, np.ndarray]:
    """Render every frame of a camera trajectory: (T, H, W, 3) uint8 RGB and (T, H, W) float32 depth."""
    return Renderer(scene, camera.K, camera.width, camera.height, ambient).render_trajectory(camera)
