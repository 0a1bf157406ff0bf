"""Egocentric RGB + depth rendering by ray casting (trimesh; embree through ``embreex`` when installed).

One ray per pixel centre (:func:`~camera.pixel_rays`); the first triangle hit gives

* depth: the z-depth of the hit in the camera frame (distance along the optical axis, metres), 0 where the
  ray hits nothing;
* RGB: the scene's vertex colours interpolated barycentrically at the hit, times a headlight shading
  ``ambient + (1 - ambient) * |n . v|`` (n the triangle normal, v the ray direction), the background
  colour where nothing is hit.
"""

from __future__ import annotations

import numpy as np

from skeleton_mamba.tasks.egodance.builder.camera import CameraTrajectory, pixel_rays
from skeleton_mamba.tasks.egodance.builder.scene import SceneMesh

__all__ = ["TriangleCache", "render_view", "render_trajectory"]


class TriangleCache:
    """Per-triangle arrays for fast shading (built once per scene, reused for every frame).

    Barycentric coordinates of a point ``p`` in triangle (v0, v0 + e1, v0 + e2) solve the 2 x 2 normal
    equations with ``d00 = e1.e1, d01 = e1.e2, d11 = e2.e2`` (Ericson, Real-Time Collision Detection 3.4).
    """

    def __init__(self, scene: SceneMesh) -> None:
        mesh = scene.mesh
        tris = np.asarray(mesh.triangles, dtype=np.float64)
        self.v0 = tris[:, 0]
        self.e1 = tris[:, 1] - tris[:, 0]
        self.e2 = tris[:, 2] - tris[:, 0]
        self.normals = np.asarray(mesh.face_normals, dtype=np.float64)
        self.d00 = np.einsum("ij,ij->i", self.e1, self.e1)
        self.d01 = np.einsum("ij,ij->i", self.e1, self.e2)
        self.d11 = np.einsum("ij,ij->i", self.e2, self.e2)
        self.inv = 1.0 / np.maximum(self.d00 * self.d11 - self.d01**2, 1e-20)
        self.colors = scene.vertex_colors[np.asarray(mesh.faces)]  # (F, 3 corners, 3 rgb)
        # everything a hit needs in one row, gathered with a single take per frame
        self.table = np.concatenate(
            [
                self.normals,
                self.v0,
                self.e1,
                self.e2,
                np.stack([self.d00, self.d01, self.d11, self.inv], 1),
                self.colors.reshape(-1, 9),
            ],
            axis=1,
        )  # (F, 25)


def render_view(
    scene: SceneMesh,
    position: np.ndarray,
    rotation: np.ndarray,
    K: np.ndarray,
    width: int,
    height: int,
    ambient: float = 0.3,
    background: tuple[int, int, int] = (0, 0, 0),
    rays: np.ndarray | None = None,
    cache: TriangleCache | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Render one view.

    Args:
        scene: the y-up scene.
        position: (3,) camera centre; rotation: (3, 3) camera-to-world (OpenCV axes).
        K: (3, 3) intrinsics; width, height: image size in pixels.
        ambient: the unlit fraction of the shading.
        background: RGB where no surface is hit.
        rays: precomputed :func:`pixel_rays` (reused across frames).
        cache: precomputed :class:`TriangleCache` of ``scene`` (reused across frames).

    Returns:
        ``(rgb, depth)``: (H, W, 3) uint8 and (H, W) float32 metres.
    """
    cam_dirs = pixel_rays(K, width, height) if rays is None else rays
    cache = TriangleCache(scene) if cache is None else cache
    position = np.asarray(position, dtype=np.float64)
    dirs = cam_dirs @ rotation.T  # world directions with unit projection on the optical axis
    tri = scene.intersector.intersects_first(np.broadcast_to(position, dirs.shape), dirs)
    hit = np.flatnonzero(tri >= 0)
    depth = np.zeros(len(dirs))
    rgb = np.tile(np.asarray(background, dtype=np.float64) / 255.0, (len(dirs), 1))
    if len(hit):
        d_hit = dirs[hit]
        row = np.take(cache.table, tri[hit], axis=0)
        normals, v0, e1, e2 = row[:, 0:3], row[:, 3:6], row[:, 6:9], row[:, 9:12]
        d00, d01, d11, inv = row[:, 12], row[:, 13], row[:, 14], row[:, 15]
        # ray parameter from the hit triangle's plane; it is the z-depth because cam_dirs have z = 1
        denom = np.einsum("ij,ij->i", normals, d_hit)
        denom = np.where(np.abs(denom) < 1e-12, 1e-12, denom)
        rel = v0 - position
        s = np.einsum("ij,ij->i", normals, rel) / denom
        depth[hit] = s
        vp = s[:, None] * d_hit - rel  # hit point relative to v0
        d20 = np.einsum("ij,ij->i", vp, e1)
        d21 = np.einsum("ij,ij->i", vp, e2)
        b1 = np.clip((d11 * d20 - d01 * d21) * inv, 0.0, 1.0)
        b2 = np.clip((d00 * d21 - d01 * d20) * inv, 0.0, 1.0)
        bary = np.stack([1.0 - b1 - b2, b1, b2], axis=1)
        albedo = np.einsum("nk,nkc->nc", bary, row[:, 16:25].reshape(-1, 3, 3))
        cos = np.abs(denom) / np.sqrt(np.einsum("ij,ij->i", d_hit, d_hit))
        rgb[hit] = albedo * (ambient + (1.0 - ambient) * cos)[:, None]
    image = (np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8).reshape(height, width, 3)
    return image, depth.astype(np.float32).reshape(height, width)


def render_trajectory(
    scene: SceneMesh, camera: CameraTrajectory, ambient: float = 0.3
) -> tuple[np.ndarray, np.ndarray]:
    """Render every frame of a camera trajectory: (T, H, W, 3) uint8 RGB and (T, H, W) float32 depth."""
    rays = pixel_rays(camera.K, camera.width, camera.height)
    cache = TriangleCache(scene)
    frames = [
        render_view(
            scene, p, r, camera.K, camera.width, camera.height, ambient=ambient, rays=rays, cache=cache
        )
        for p, r in zip(camera.positions, camera.rotations)
    ]
    return np.stack([f[0] for f in frames]), np.stack([f[1] for f in frames])
