"""Body-scene penetration score ``S_p`` ([EgoMusic] supp. Sec. 5: reject a placement when ``S_p > 2``).

The paper scores the SMPL body mesh "using a method by [34]" ([SceneMotion]) without giving the
formula; this module's definition, the project's choice, is

    S_p = 100 * max over frames t and body spheres i of max(0, r_i - sdf(c_i(t)))      [centimetres]

i.e. the deepest intrusion of the body into the scene over the whole subsequence, in centimetres, so the
paper's threshold 2 means "no body part goes more than 2 cm into the scene in any frame". It does not
depend on how densely the body is sampled.

* The body, by default: capsules along the 23 SMPL-24 bones (:data:`BONE_RADII`, rough adult
  proportions, metres) plus a head sphere, each capsule approximated by spheres of its radius spaced at
  most one radius apart (the union of spheres lies within ``0.14 r`` of the capsule surface).
* With a user-supplied SMPL model (``--smpl-model``, :mod:`.body_mesh`): the mesh vertices, spheres of
  radius 0, so the same definition reads ``S_p = 100 * max_t,v max(0, -sdf(v(t)))``
  (:func:`mesh_penetration_score`). Evaluating ``sdf`` at every vertex of every frame would cost
  26 rays x 6890 vertices per frame, so vertices are screened first, exactly: ``sdf`` is 1-Lipschitz,
  so a vertex at distance ``d`` from its anchor joint (largest skinning weight) with ``sdf(joint) > d``
  is outside; of the others, a vertex whose anchor joint is outside and whose segment joint -> vertex
  crosses no scene triangle (one ray) is on the joint's side, outside too. Only the remaining vertices
  get the full ``sdf``. A free-standing body leaves a few foot vertices near the floor.
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

__all__ = [
    "BONE_RADII",
    "HEAD_RADIUS",
    "FOOT_RADIUS",
    "body_spheres",
    "signed_distance",
    "penetration_score",
    "mesh_penetration_depths",
    "mesh_penetration_score",
]

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
    tri = scene.caster.first_hits(origins, np.tile(_DIRECTIONS, (n, 1))).tri.astype(np.int64)
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


def mesh_penetration_depths(
    scene: SceneMesh, vertices: np.ndarray, joints: np.ndarray, anchor: np.ndarray
) -> np.ndarray:
    """Per-frame deepest intrusion (T,) in metres of mesh vertices into the scene (module docstring).

    Args:
        scene: the y-up scene.
        vertices: (T, V, 3) placed mesh vertices.
        joints: (T, J, 3) placed joints the vertices are skinned to.
        anchor: (V,) joint index of each vertex (largest skinning weight).
    """
    t, v = vertices.shape[:2]
    joint_sdf = signed_distance(scene, joints.reshape(-1, 3)).reshape(t, -1)[:, anchor]  # (T, V)
    anchor_pos = joints[:, anchor]  # (T, V, 3)
    reach = vertices - anchor_pos
    reach_len = np.linalg.norm(reach, axis=-1)
    candidate = (joint_sdf - reach_len <= 0.0).reshape(-1)  # others are outside (1-Lipschitz bound)
    outside_joint = (joint_sdf > 0.0).reshape(-1)
    exact = candidate & ~outside_joint
    seg = np.flatnonzero(candidate & outside_joint & (reach_len.reshape(-1) > 1e-9))
    if len(seg):
        hits = scene.caster.first_hits(anchor_pos.reshape(-1, 3)[seg], reach.reshape(-1, 3)[seg])
        exact[seg[(hits.tri >= 0) & (hits.t <= 1.0)]] = True  # the segment joint -> vertex is crossed
    depth = np.zeros(t * v)
    if exact.any():
        depth[exact] = np.maximum(0.0, -signed_distance(scene, vertices.reshape(-1, 3)[exact]))
    return depth.reshape(t, v).max(axis=1)


def mesh_penetration_score(
    scene: SceneMesh,
    vertices: np.ndarray,
    joints: np.ndarray,
    anchor: np.ndarray,
    frame_stride: int = 1,
    stop_above: float | None = None,
    chunk: int = 16,
) -> float:
    """``S_p`` in centimetres of a placed SMPL mesh sequence (module docstring).

    Args:
        scene: the y-up scene.
        vertices: (T, V, 3) placed mesh vertices; joints: (T, 24, 3) placed model joints.
        anchor: (V,) joint index of each vertex (largest skinning weight).
        frame_stride: score every ``frame_stride``-th frame only.
        stop_above: stop at the first chunk of ``chunk`` frames whose score exceeds this value (cm);
            the result is then a lower bound of ``S_p``, still above ``stop_above`` (a body deep in a
            wall would otherwise need the full ``sdf`` of every vertex of every frame).
    """
    if vertices.ndim != 3 or joints.ndim != 3 or joints.shape[:1] != vertices.shape[:1]:
        raise ValueError(f"vertices (T, V, 3) and joints (T, J, 3) expected: {vertices.shape} {joints.shape}")
    vertices, joints = vertices[::frame_stride], joints[::frame_stride]
    score = 0.0
    for start in range(0, len(vertices), chunk):
        part = slice(start, start + chunk)
        depths = mesh_penetration_depths(scene, vertices[part], joints[part], anchor)
        score = max(score, 100.0 * float(depths.max()))
        if stop_above is not None and score > stop_above:
            break
    return score
