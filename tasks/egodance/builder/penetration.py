"""Body-scene penetration score ``S_p`` (seed supplement section 5: reject a placement when ``S_p > 2``).

The seed scores the SMPL body mesh "using a method by [34]" (Wang et al., CVPR 2021) without giving the
formula; this module's definition, the project's choice, is

    S_p = 100 * max over frames t and body spheres i of max(0, r_i - sdf(c_i(t)))      [centimetres]

i.e. the deepest intrusion of the body into the scene over the whole subsequence, in centimetres, so the
seed's threshold 2 means "no body part goes more than 2 cm into the scene in any frame". It does not
depend on how densely the body is sampled.

* The body: capsules along the 23 SMPL-24 bones (:data:`BONE_RADII`, rough adult proportions, metres) plus
  a head sphere, each capsule approximated by spheres of its radius spaced at most one radius apart
  (the union of spheres lies within ``0.14 r`` of the capsule surface). A user-supplied SMPL body mesh
  is NOT supported: the official SMPL ``.pkl`` needs chumpy (unsafe to unpickle here), and skinning the
  ``.npz`` variant would need the model's own joint regressor and blend weights; capsules are used.
* ``sdf``: the signed distance to the scene surface (:func:`signed_distance`), its magnitude from the
  closest point on candidate triangles found by ray casting and its sign from the normal of the
  closest triangle (negative = behind the surface = inside an object or behind a wall). This works for
  open scanned scenes (Replica) whose normals face the free space, where a watertight inside test is
  impossible, and needs no spatial-index package (trimesh's own closest-point query needs ``rtree``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.egodance.builder.scene import SceneMesh

__all__ = ["BONE_RADII", "HEAD_RADIUS", "FOOT_RADIUS", "body_spheres", "signed_distance", "penetration_score"]

# Capsule radius (metres) of the bone ending at each child joint (index = child joint; 0 has no bone).
BONE_RADII: tuple[float, ...] = (
    0.0,  # pelvis (root)
    0.09,
    0.09,  # pelvis -> hips
    0.11,  # pelvis -> spine1
    0.07,
    0.07,  # thighs
    0.11,  # spine1 -> spine2
    0.05,
    0.05,  # shins
    0.11,  # spine2 -> spine3
    0.04,
    0.04,  # feet (ankle -> toes)
    0.06,  # neck
    0.06,
    0.06,  # spine3 -> collars
    0.09,  # neck -> head
    0.06,
    0.06,  # collars -> shoulders
    0.05,
    0.05,  # upper arms
    0.04,
    0.04,  # forearms
    0.04,
    0.04,  # hands
)
HEAD_RADIUS = 0.10  # sphere centred on the head joint (15)
FOOT_RADIUS = 0.04  # radius of the ankle -> toe capsules: placement puts the lowest foot joint this high
FOOT_JOINTS = (7, 8, 10, 11)  # left/right ankle, left/right toes


@dataclass(frozen=True)
class SphereSet:
    """Spheres attached to bones: centre = joints[a] + s * (joints[b] - joints[a]), radius r."""

    start: np.ndarray  # (S,) joint index a
    end: np.ndarray  # (S,) joint index b
    fraction: np.ndarray  # (S,) s in [0, 1]
    radius: np.ndarray  # (S,)

    def centres(self, joints: np.ndarray) -> np.ndarray:
        """(..., 24, 3) joints -> (..., S, 3) sphere centres."""
        a, b = joints[..., self.start, :], joints[..., self.end, :]
        return a + self.fraction[:, None] * (b - a)


def body_spheres(joints: np.ndarray) -> SphereSet:
    """Spheres covering the capsule body of a motion, spaced from its longest bone lengths.

    Args:
        joints: (T, 24, 3) joint positions (bone lengths are taken as the maximum over frames).
    """
    start, end, fraction, radius = [15], [15], [0.0], [HEAD_RADIUS]
    for parent, child in SMPL24.bones():
        r = BONE_RADII[child]
        length = float(np.linalg.norm(joints[:, child] - joints[:, parent], axis=-1).max())
        n = int(np.ceil(length / r)) + 1
        start += [parent] * n
        end += [child] * n
        fraction += list(np.linspace(0.0, 1.0, n))
        radius += [r] * n
    return SphereSet(np.array(start), np.array(end), np.array(fraction), np.array(radius))


# The 26 directions of the 3 x 3 x 3 grid around a point, used to find candidate nearest triangles.
_DIRECTIONS = np.array(
    [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)]
)
_DIRECTIONS = _DIRECTIONS / np.linalg.norm(_DIRECTIONS, axis=1, keepdims=True)


def signed_distance(scene: SceneMesh, points: np.ndarray) -> np.ndarray:
    """Signed distance (N,) of points (N, 3) to the scene surface, negative behind the closest triangle.

    Candidate triangles are those hit by 26 rays from each point (embree ray casting); the distance is
    the exact point-triangle distance to the nearest candidate (``trimesh.triangles.closest_point``)
    and the sign that of the offset along its normal. For a point near a surface the nearest triangle
    is hit by a ray unless the surface is tessellated finer than the ray spacing, where a neighbouring
    triangle a little farther away is found. Points whose rays hit nothing get ``+inf``.
    """
    n, d = len(points), len(_DIRECTIONS)
    mesh = scene.mesh
    origins = np.repeat(points, d, axis=0)
    tri = scene.intersector.intersects_first(origins, np.tile(_DIRECTIONS, (n, 1)))
    hit = np.flatnonzero(tri >= 0)
    result = np.full(n, np.inf)
    if len(hit) == 0:
        return result
    point_idx, tri = hit // d, tri[hit]
    normals = mesh.face_normals[tri]
    rel = mesh.vertices[mesh.faces[tri, 0]] - points[point_idx]
    plane = np.einsum("ij,ij->i", normals, rel)  # signed offset of the plane along its normal
    cos = np.einsum("ij,ij->i", normals, _DIRECTIONS[hit % d])
    ray_t = np.where(np.abs(cos) > 1e-12, plane / np.where(cos == 0, 1.0, cos), np.inf)  # hit distance
    # the hit point lies on the surface, so the distance is at most the nearest hit; a triangle whose
    # plane is farther than that cannot be the closest one
    upper = np.full(n, np.inf)
    np.minimum.at(upper, point_idx, np.abs(ray_t))
    keep = np.abs(plane) <= upper[point_idx] + 1e-9
    # many rays of one point hit the same triangle: evaluate each (point, triangle) pair once
    key = np.unique(point_idx[keep].astype(np.int64) * len(mesh.faces) + tri[keep])
    p_idx, t_idx = key // len(mesh.faces), key % len(mesh.faces)
    pts = points[p_idx]
    offset = pts - trimesh.triangles.closest_point(mesh.triangles[t_idx], pts)
    dist = np.linalg.norm(offset, axis=1)
    side = np.einsum("ij,ij->i", offset, mesh.face_normals[t_idx])
    signed = np.where(side < 0, -dist, dist)
    # per point, the pair with the smallest distance (keys are sorted by point; then by distance)
    order = np.lexsort((dist, p_idx))
    first = np.ones(len(order), dtype=bool)
    first[1:] = p_idx[order[1:]] != p_idx[order[:-1]]
    chosen = order[first]
    result[p_idx[chosen]] = signed[chosen]
    return result


def penetration_depths(scene: SceneMesh, joints: np.ndarray, spheres: SphereSet | None = None) -> np.ndarray:
    """Per-frame deepest intrusion (T,) in metres of the capsule body (joints (T, 24, 3)) into the scene."""
    spheres = spheres or body_spheres(joints)
    centres = spheres.centres(joints)  # (T, S, 3)
    t, s = centres.shape[:2]
    # Only spheres whose centre is within the scene's bounding box (grown by the radius) can touch it.
    lo, hi = scene.mesh.bounds
    grow = spheres.radius.max()
    flat = centres.reshape(-1, 3)
    near = np.all((flat >= lo - grow) & (flat <= hi + grow), axis=1)
    depth = np.zeros(t * s)
    if near.any():
        sdf = signed_distance(scene, flat[near])
        depth[near] = np.maximum(0.0, np.tile(spheres.radius, t)[near] - sdf)
    return depth.reshape(t, s).max(axis=1)


def penetration_score(scene: SceneMesh, joints: np.ndarray, frame_stride: int = 1) -> float:
    """``S_p`` in centimetres (module docstring) of a placed motion, joints (T, 24, 3) in scene coordinates.

    Args:
        scene: the y-up scene.
        joints: (T, 24, 3) placed SMPL-24 joints.
        frame_stride: score every ``frame_stride``-th frame only (faster, may miss brief contacts).
    """
    if joints.ndim != 3 or joints.shape[1:] != (24, 3):
        raise ValueError(f"joints must be (T, 24, 3), got {joints.shape}")
    subset = joints[::frame_stride]
    return 100.0 * float(penetration_depths(scene, subset, body_spheres(joints)).max())
