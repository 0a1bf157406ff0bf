"""First hits of many rays against a triangle mesh: embree (``embreex``) when installed, trimesh otherwise.

Embree is called directly (``EmbreeScene.run(..., output=1)``), which returns, per ray, the triangle,
the ray parameter and the barycentric coordinates of the first hit in one pass, faster than trimesh's
embree-backed queries.
The directions are NOT normalised: the ray parameter ``t`` of a hit is in units of the direction, so
camera rays with unit z give the z-depth directly, and a segment ``a -> b`` cast as ``(a, b - a)`` is
crossed when ``t <= 1``.

Embree works in float32; the vertices are shifted to the mesh's lower bounding-box corner first (as
trimesh does), so room-sized scenes keep sub-millimetre precision.

Without embree (no ``embreex`` wheel for the platform, or ``SKELETON_MAMBA_RAY_CASTER=trimesh``) trimesh's
numpy caster is used. Its broad phase lists, for every ray, each triangle whose box meets the ray's box
(Python lists, then about 400 bytes per ray-triangle pair in the narrow phase), so one call over a whole
frame or a penetration test grew to tens of GB. It is called on chunks of at most
``max(1, pair_budget // F)`` rays (F triangles), so a call holds at most ``pair_budget`` pairs whatever the
scene (about 100 MB for the default 2**18).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import trimesh
from trimesh.ray.ray_triangle import RayMeshIntersector

__all__ = ["FirstHits", "RayCaster", "HAS_EMBREE", "RAY_CASTER_ENV", "resolve_backend"]

# Environment variable choosing the ray caster: "auto" (embree when installed), "embree" or "trimesh".
RAY_CASTER_ENV = "SKELETON_MAMBA_RAY_CASTER"

try:
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    HAS_EMBREE = True
except ImportError:  # pragma: no cover - platforms without an embreex wheel (pyproject markers)
    HAS_EMBREE = False


def resolve_backend(backend: str | None = None) -> str:
    """The ray caster to use: ``backend``, else ``$SKELETON_MAMBA_RAY_CASTER``, else ``"auto"``.

    Returns ``"embree"`` or ``"trimesh"``; ``"auto"`` is embree when ``embreex`` is importable.
    """
    choice = (backend or os.environ.get(RAY_CASTER_ENV) or "auto").strip().lower()
    if choice not in ("auto", "embree", "trimesh"):
        raise ValueError(
            f"ray caster {choice!r} (argument or ${RAY_CASTER_ENV}): use auto, embree or trimesh"
        )
    if choice == "auto":
        return "embree" if HAS_EMBREE else "trimesh"
    if choice == "embree" and not HAS_EMBREE:
        raise ImportError(f"{RAY_CASTER_ENV}=embree but embreex is not installed (pip install embreex)")
    return choice


@dataclass
class FirstHits:
    """The first hit of every ray (N rays).

    Attributes:
        tri: (N,) int triangle index, -1 where the ray hits nothing.
        t: (N,) float32 ray parameter of the hit (``hit = origin + t * direction``), undefined on misses.
        u, v: (N,) float32 barycentric coordinates: ``hit = (1 - u - v) a + u b + v c`` for the
            triangle's corners (a, b, c) in face order; undefined on misses.
    """

    tri: np.ndarray
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray


class RayCaster:
    """Casts rays against one mesh, built once (the BVH) and reused for every query.

    Args:
        vertices: (V, 3) float mesh vertices.
        faces: (F, 3) int triangle vertex indices.
        backend: ``"auto"``, ``"embree"`` or ``"trimesh"`` (:func:`resolve_backend`; default: the
            environment variable ``SKELETON_MAMBA_RAY_CASTER``, else auto).
        pair_budget: trimesh caster only: the most ray-triangle candidate pairs one call may hold
            (module docstring); ``chunk_rays`` is derived from it.
    """

    def __init__(
        self, vertices: np.ndarray, faces: np.ndarray, backend: str | None = None, pair_budget: int = 2**18
    ) -> None:
        vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.origin = vertices.min(axis=0)
        self.backend = resolve_backend(backend)
        self.chunk_rays = max(1, pair_budget // max(1, len(self.faces)))
        if self.backend == "embree":
            self._scene = rtcore_scene.EmbreeScene()
            TriangleMesh(
                scene=self._scene,
                vertices=np.ascontiguousarray(vertices - self.origin, dtype=np.float32),
                indices=np.ascontiguousarray(self.faces, dtype=np.int32),
            )
        else:
            try:
                import rtree  # noqa: F401  # lazy: the fallback caster needs rtree
            except ImportError as err:
                raise ImportError(
                    "trimesh's ray caster (used without embreex) needs rtree: pip install rtree"
                ) from err
            self._mesh = trimesh.Trimesh(vertices=vertices, faces=self.faces, process=False)
            self._trimesh = RayMeshIntersector(self._mesh)

    def first_hits(self, origins: np.ndarray, directions: np.ndarray) -> FirstHits:
        """First hits of rays ``origins + t * directions`` (both (N, 3); origins may be broadcast (3,))."""
        directions = np.asarray(directions)
        origins = np.asarray(origins, dtype=np.float64)
        if self.backend == "trimesh":
            return self._first_hits_trimesh(np.broadcast_to(origins, directions.shape), directions)
        origins = origins - self.origin
        start = np.empty(directions.shape, dtype=np.float32)  # embree wants contiguous float32 rows
        start[...] = origins
        out = self._scene.run(start, np.ascontiguousarray(directions, dtype=np.float32), output=1)
        return FirstHits(out["primID"], out["tfar"], out["u"], out["v"])

    def _first_hits_trimesh(self, origins: np.ndarray, directions: np.ndarray) -> FirstHits:
        """trimesh's caster, called on chunks of ``chunk_rays`` rays (module docstring)."""

        n = len(directions)
        tri = np.full(n, -1, dtype=np.int64)
        t, u, v = (np.zeros(n, dtype=np.float32) for _ in range(3))
        for start in range(0, n, self.chunk_rays):
            o, d = origins[start : start + self.chunk_rays], directions[start : start + self.chunk_rays]
            index_tri, index_ray, locations = self._trimesh.intersects_id(
                o, d, multiple_hits=False, return_locations=True
            )
            if len(index_ray):
                d = d[index_ray]
                along = np.einsum("ij,ij->i", locations - o[index_ray], d)
                bary = trimesh.triangles.points_to_barycentric(self._mesh.triangles[index_tri], locations)
                index_ray = index_ray + start
                tri[index_ray] = index_tri
                t[index_ray] = along / np.einsum("ij,ij->i", d, d)
                u[index_ray], v[index_ray] = bary[:, 1], bary[:, 2]
        return FirstHits(tri, t, u, v)
