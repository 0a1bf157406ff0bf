"""A character's skinned mesh posed frame by frame (``sm render`` of ``sm retarget``'s output): the mesh that
moves, not a stick figure.

Read through the toolkit's bounded glTF reader (:mod:`skeleton_mamba.tasks.motion.formats.gltf_read`: the
file's layout checked as the Khronos validator checks it before any value is read): every node binding a
triangle primitive (``TRIANGLES``, or a strip / fan unrolled) to a skin, its ``POSITION``, ``JOINTS_0``,
``WEIGHTS_0`` and indices, and the skin's joints and inverse bind matrices; the first animation, one key per
frame on any node's translation or rotation (:func:`~skeleton_mamba.tasks.motion.formats.gltf_read.read_glb`'s
rule). A frame's vertices are glTF's linear blend skinning,

    v_world(t) = sum_i w_i * W(joint_i, t) @ IBM_i @ v,

with ``W`` the joint node's world matrix (``parent @ T R S`` down the node tree) at frame ``t``; the mesh
node's own transform does not apply (glTF 2.0, skins).
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.tasks.motion.body.rotations import quaternion_to_matrix
from skeleton_mamba.tasks.motion.formats.gltf_read import (
    _animation,
    _frame_rate,
    _load,
    _Reader,
    check_layout,
)
from skeleton_mamba.tasks.motion.render.character import skinned_triangles

__all__ = ["CharacterMesh", "read_character_mesh"]


@dataclass
class CharacterMesh:
    """The skinned triangles of a character and its animation (module docstring).

    Attributes:
        vertices: (V, 3) bind-pose positions; triangles: (F, 3) vertex indices.
        influences: (V, 4) indices into ``joint_nodes`` / ``inverse_bind``; weights: (V, 4), rows sum to 1.
        joint_nodes: (K,) the node of each influence; inverse_bind: (K, 4, 4).
        world: (T, N, 4, 4) every node's world matrix per frame; parents: (N,) node parents (-1: a root).
        fps: the animation's frame rate.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    influences: np.ndarray
    weights: np.ndarray
    joint_nodes: np.ndarray
    inverse_bind: np.ndarray
    world: np.ndarray
    parents: np.ndarray
    fps: float

    @property
    def num_frames(self) -> int:
        return len(self.world)

    def posed(self, t: int) -> np.ndarray:
        """(V, 3) world positions of the vertices at frame ``t`` (linear blend skinning)."""
        skinning = self.world[t, self.joint_nodes] @ self.inverse_bind  # (K, 4, 4)
        blend = np.einsum("vk,vkij->vij", self.weights, skinning[self.influences])
        return np.einsum("vij,vj->vi", blend[:, :3, :3], self.vertices) + blend[:, :3, 3]

    def joint_positions(self) -> np.ndarray:
        """(T, K', 3) world positions of the skin joints (each node once), for a camera to frame them."""
        nodes = np.unique(self.joint_nodes)
        return self.world[:, nodes][..., :3, 3]


def _triangles(mode: int | None, indices: np.ndarray) -> np.ndarray:
    if mode in (None, 4):
        return indices[: len(indices) // 3 * 3].reshape(-1, 3)
    k = np.arange(len(indices) - 2)
    if mode == 5:  # a strip: every other triangle flipped to keep its winding
        tri = np.stack([indices[k], indices[k + 1], indices[k + 2]], 1)
        tri[1::2] = tri[1::2][:, [1, 0, 2]]
        return tri
    return np.stack([np.full_like(k, indices[0]), indices[k + 1], indices[k + 2]], 1)  # a fan


def _world(r: _Reader, parents: np.ndarray) -> tuple[np.ndarray, float]:
    """(T, N, 4, 4) node world matrices per frame of the first animation, and its frame rate."""
    nodes = r.gltf.nodes
    times, tracks = _animation(r, {n: n for n in range(len(nodes))})
    frames = len(times)
    local = np.zeros((frames, len(nodes), 4, 4))
    for n, node in enumerate(nodes):
        if node.matrix is not None:
            local[:, n] = np.asarray(node.matrix, np.float64).reshape(4, 4).T  # column-major
            continue
        t = np.broadcast_to(np.asarray(node.translation or [0.0, 0.0, 0.0], np.float64), (frames, 3))
        q = np.broadcast_to(np.asarray(node.rotation or [0.0, 0.0, 0.0, 1.0], np.float64), (frames, 4))
        t, q = tracks.get((n, "translation"), t), tracks.get((n, "rotation"), q)
        rotation = quaternion_to_matrix(torch.from_numpy(np.ascontiguousarray(q[:, [3, 0, 1, 2]]))).numpy()
        local[:, n, :3, :3] = rotation * np.asarray(node.scale or [1.0, 1.0, 1.0], np.float64)[None, None, :]
        local[:, n, :3, 3] = t
        local[:, n, 3, 3] = 1.0
    world = np.zeros_like(local)
    done = np.zeros(len(nodes), bool)

    def visit(n: int) -> None:
        if not done[n]:
            if parents[n] >= 0:
                visit(parents[n])
            world[:, n] = local[:, n] if parents[n] < 0 else world[:, parents[n]] @ local[:, n]
            done[n] = True

    for n in range(len(nodes)):
        visit(n)
    return world, _frame_rate(r, times)


def read_character_mesh(path: str | PathLike[str]) -> CharacterMesh:
    """The skinned triangles and animation of a character ``.glb`` / ``.vrm`` (module docstring).

    Raises:
        GltfError: a malformed file, no skinned triangle mesh, an animation that is not one key per frame.
    """
    path = Path(path)
    gltf, blob = _load(path)
    r = _Reader(path, gltf, blob)
    check_layout(r)
    parents = np.full(len(gltf.nodes), -1)
    for p, node in enumerate(gltf.nodes):
        for c in node.children or []:
            c = r.index(c, gltf.nodes, f"node {p} child")
            if parents[c] != -1 or c == p:
                raise r.fail(f"node {c} has two parents")
            parents[c] = p
    vertices, triangles, influences, weights = [], [], [], []
    joint_nodes, inverse_bind = [], []
    for node in gltf.nodes:
        if node.skin is None or node.mesh is None:
            continue
        skin = gltf.skins[r.index(node.skin, gltf.skins, "skin")]
        joints = [r.index(j, gltf.nodes, "skin joint node") for j in skin.joints or []]
        ibm = (
            r.values(skin.inverseBindMatrices, ("MAT4",)).reshape(-1, 4, 4).transpose(0, 2, 1)
            if skin.inverseBindMatrices is not None
            else np.tile(np.eye(4), (len(joints), 1, 1))
        )
        if len(ibm) != len(joints):
            raise r.fail(f"skin {node.skin}: {len(ibm)} inverse bind matrices for {len(joints)} joints")
        for primitive in gltf.meshes[r.index(node.mesh, gltf.meshes, "mesh")].primitives:
            if not skinned_triangles(primitive):
                continue
            a = primitive.attributes
            position = r.values(a.POSITION, ("VEC3",))
            index = r.values(primitive.indices, ("SCALAR",))[:, 0] if primitive.indices is not None else None
            index = np.arange(len(position)) if index is None else index
            joint, weight = r.values(a.JOINTS_0, ("VEC4",)), r.values(a.WEIGHTS_0, ("VEC4",))
            if len(joint) != len(position) or len(weight) != len(position) or index.max() >= len(position):
                raise r.fail("a skinned primitive's attributes or indices do not match its positions")
            if joint.max() >= len(joints) or joint.min() < 0:
                raise r.fail(f"JOINTS_0 names a joint outside skin {node.skin}'s {len(joints)}")
            total = weight.sum(1, keepdims=True)
            triangles.append(_triangles(primitive.mode, index) + sum(len(v) for v in vertices))
            vertices.append(position)
            influences.append(joint + len(joint_nodes))
            weights.append(np.where(total > 0, weight / np.maximum(total, 1e-12), [1.0, 0.0, 0.0, 0.0]))
        joint_nodes.extend(joints)
        inverse_bind.append(ibm)
    if not vertices:
        raise r.fail("holds no skinned triangle mesh: not a character")
    world, fps = _world(r, parents)
    return CharacterMesh(
        np.concatenate(vertices), np.concatenate(triangles), np.concatenate(influences),
        np.concatenate(weights), np.asarray(joint_nodes), np.concatenate(inverse_bind), world, parents, fps,
    )  # fmt: skip
