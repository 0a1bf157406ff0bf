"""Retarget a motion onto a humanoid rig (``sm retarget``): each mapped bone points where the source's points.

From the source's joint positions (forward kinematics in metres,
:mod:`skeleton_mamba.tasks.motion.formats.motion_reader`), for every humanoid bone both the source and the rig
have (:mod:`.rig`) a world *delta* rotation ``D`` (T, 3, 3) is chosen that takes the bone's rest direction on
the rig (to its nearest mapped descendant, its *tip*) to the source's direction of the same bone in that
frame:

- ``hips``: the frame of (direction to its tip, left-right hip axis) at rest to the same frame in the source;
- ``spine``, ``chest``, ``upperChest``, ``neck``: likewise with the shoulder axis as second direction;
- every other bone: the shortest rotation from its rest direction carried by its parent's delta to the
  source's direction, after the parent's delta (so the twist is the parent's: continuous, no flips);
- an unmapped bone, or one without a tip (hands, head, toes without a toe end, a bone whose nearest mapped
  descendant sits on it): its parent's delta.

A node's posed world rotation is ``D @ W_rest`` and its local rotation ``(D_p W_rest_p)^T D W_rest``, so the
bones' rolls at rest and the rest pose (T or A) do not matter, and unmapped nodes keep their rest. The hips
follow the source's path scaled by the ratio of the leg lengths (thigh + shin), lifted so that the
rig's ankles are at the source's ankle heights scaled where the source's feet are on the floor
(:func:`_floor_lift`: a few centimetres that absorb the difference of proportions, smooth in time).
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
import pygltflib

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.atomic import atomic_path
from skeleton_mamba.tasks.motion.retarget.rig import BONES, Rig

__all__ = ["Retarget", "bone_direction_errors", "driven_tips", "retarget", "write_bvh_rig", "write_gltf_rig"]

_TORSO = ("spine", "chest", "upperChest", "neck")
_TIPS = {
    "hips": ("spine", "chest", "upperChest", "neck", "head"),
    "spine": ("chest", "upperChest", "neck", "head"),
    "chest": ("upperChest", "neck", "head"),
    "upperChest": ("neck", "head"),
    "neck": ("head",),
    **{f"{s}Shoulder": (f"{s}UpperArm",) for s in ("left", "right")},
    **{f"{s}UpperArm": (f"{s}LowerArm",) for s in ("left", "right")},
    **{f"{s}LowerArm": (f"{s}Hand",) for s in ("left", "right")},
    **{f"{s}UpperLeg": (f"{s}LowerLeg",) for s in ("left", "right")},
    **{f"{s}LowerLeg": (f"{s}Foot",) for s in ("left", "right")},
    **{f"{s}Foot": (f"{s}Toes",) for s in ("left", "right")},
}
_EPS = 1e-6


@dataclass
class Retarget:
    """The rig's motion.

    Attributes:
        local: rig node -> (T, 3, 3) its local rotations (scale factored out), for the driven nodes; the
            others keep their rest.
        hips_translation: (T, 3) local translation of the hips node.
        positions: (T, N, 3) world positions of the rig's nodes, metres.
        scale: the leg-length ratio rig / source.
        driven: humanoid bone -> (rig node, source joint, tip bone) of the bones given a direction.
    """

    local: dict[int, np.ndarray]
    hips_translation: np.ndarray
    positions: np.ndarray
    scale: float
    driven: dict[str, tuple[int, int, str]]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), _EPS)


def _frame(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """(..., 3, 3) orthonormal frames, columns (primary, secondary made orthogonal, their cross product)."""
    e1 = _unit(primary)
    e2 = _unit(secondary - np.sum(secondary * e1, -1, keepdims=True) * e1)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=-1)


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3, 3) shortest rotations taking ``a`` to ``b`` (Rodrigues; a half-turn about a normal)."""
    a, b = _unit(a), _unit(b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=-1)
    c = np.sum(a * b, -1)
    k = axis / np.maximum(s, _EPS)[..., None]
    # a and b opposite: any axis normal to a
    other = np.where(np.abs(a[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    k = np.where((s < 1e-9)[..., None] & (c < 0)[..., None], _unit(np.cross(a, other)), k)
    angle = np.arctan2(s, c)
    kx = np.zeros(a.shape[:-1] + (3, 3))
    kx[..., 0, 1], kx[..., 0, 2], kx[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    kx = kx - np.swapaxes(kx, -1, -2)
    eye = np.eye(3)
    sin, cos = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return eye + sin * kx + (1 - cos) * (kx @ kx)


def _rotation(world: np.ndarray) -> np.ndarray:
    """The rotation part of (N, 4, 4) rest matrices with a uniform scale."""
    m = world[..., :3, :3]
    return m / np.cbrt(np.linalg.det(m))[..., None, None]


def driven_tips(rig: Rig, positions: np.ndarray, names_to_bones: dict[str, int]) -> dict[str, str]:
    """Humanoid bone -> its tip, for the bones both ``rig`` and the source (``positions`` (T, J, 3),
    ``names_to_bones``) have that are given a direction: the nearest mapped bone of :data:`_TIPS`, none when
    it sits on this one (a CMU chest and neck) on the rig or in the source (median length)."""
    rest_pos = rig.rest_world[:, :3, 3]
    both = [b for b in BONES if b in rig.bones and b in names_to_bones]
    tips = {}
    for b in both:
        t = next((t for t in _TIPS.get(b, ()) if t in both), None)
        if t is None:
            continue
        rig_length = np.linalg.norm(rest_pos[rig.bones[t]] - rest_pos[rig.bones[b]])
        source = positions[:, names_to_bones[t]] - positions[:, names_to_bones[b]]
        if min(rig_length, np.median(np.linalg.norm(source, axis=-1))) > 1e-4:
            tips[b] = t
    return tips


def retarget(rig: Rig, positions: np.ndarray, names_to_bones: dict[str, int]) -> Retarget:
    """Retarget source joint ``positions`` (T, J, 3), metres +Y up, with humanoid bones ``names_to_bones``
    (bone -> source joint), onto ``rig`` (module docstring)."""
    positions = np.asarray(positions, np.float64)
    frames = len(positions)
    rest_pos = rig.rest_world[:, :3, 3]
    rest_rot = _rotation(rig.rest_world)
    both = [b for b in BONES if b in rig.bones and b in names_to_bones]
    tips = driven_tips(rig, positions, names_to_bones)

    def src(b: str) -> np.ndarray:
        return positions[:, names_to_bones[b]]

    def rest(b: str) -> np.ndarray:
        return rest_pos[rig.bones[b]]

    hip_axis = (rest("leftUpperLeg") - rest("rightUpperLeg"), src("leftUpperLeg") - src("rightUpperLeg"))
    shoulders = all(f"{s}UpperArm" in both for s in ("left", "right"))
    shoulder_axis = (
        (rest("leftUpperArm") - rest("rightUpperArm"), src("leftUpperArm") - src("rightUpperArm"))
        if shoulders
        else None
    )
    node_bone = {rig.bones[b]: b for b in both}
    n = len(rig.names)
    delta = np.zeros((frames, n, 3, 3))
    driven: dict[str, tuple[int, int, str]] = {}
    hips = rig.bones["hips"]
    for j in rig.order:
        p = rig.parents[j]
        parent_delta = delta[:, p] if p >= 0 else np.broadcast_to(np.eye(3), (frames, 3, 3))
        b = node_bone.get(j)
        t = tips.get(b) if b is not None else None
        if t is None:
            delta[:, j] = parent_delta
            continue
        driven[b] = (j, names_to_bones[b], t)
        rest_dir, cur_dir = rest(t) - rest(b), src(t) - src(b)
        second = hip_axis if b == "hips" else shoulder_axis if b in _TORSO else None
        if second is not None:
            delta[:, j] = _frame(cur_dir, second[1]) @ _frame(rest_dir, second[0]).T
        else:
            carried = parent_delta @ rest_dir
            delta[:, j] = _swing(carried, cur_dir) @ parent_delta
    local = {}  # the driven nodes' only: every other node keeps its rest (its delta is its parent's)
    for j, _, _ in driven.values():
        p = rig.parents[j]
        world = delta[:, j] @ rest_rot[j]
        local[j] = world if p < 0 else np.swapaxes(delta[:, p] @ rest_rot[p], -1, -2) @ world

    scale = _leg_length(rest, None) / max(_leg_length(None, src), _EPS)
    path = scale * src("hips")
    posed = _posed(rig, delta, path)
    feet = [rig.bones[f] for f in ("leftFoot", "rightFoot")]
    source_feet = np.stack([src("leftFoot"), src("rightFoot")], 1)[..., 1] * scale
    lift = _floor_lift(source_feet, posed[:, feet, 1], scale)
    path[:, 1] += lift
    posed[..., 1] += np.where(_below_hips(rig, hips), lift[:, None], 0.0)
    parent = rig.parents[hips]
    inverse = np.linalg.inv(rig.rest_world[parent]) if parent >= 0 else np.eye(4)
    hips_translation = path @ inverse[:3, :3].T + inverse[:3, 3]
    return Retarget(local, hips_translation, posed, scale, driven)


def _floor_lift(source_feet: np.ndarray, rig_feet: np.ndarray, scale: float) -> np.ndarray:
    """(T,) heights to add to the hips so that the rig's ankles (T, 2) are at the source's scaled ankle
    heights (T, 2) when those are on the floor: a constant (the median difference over the contact frames,
    a source ankle within 2 cm of its lowest), plus per frame the difference at the feet on the floor,
    weighted by how close to the floor each is (smooth: a Gaussian of the height, 1 cm wide)."""
    height = source_feet - source_feet.min(axis=0)
    error = source_feet - rig_feet
    contact = height <= 0.02 * scale
    constant = float(np.median(error[contact])) if contact.any() else float(np.median(error))
    weight = np.exp(-0.5 * (height / (0.01 * scale)) ** 2)
    return (np.sum(weight * error, 1) + 1e-3 * constant) / (np.sum(weight, 1) + 1e-3)


def _leg_length(rest, src) -> float:
    total = []
    for s in ("left", "right"):
        chain = (f"{s}UpperLeg", f"{s}LowerLeg", f"{s}Foot")
        for a, b in zip(chain, chain[1:]):
            if rest is not None:
                total.append(np.linalg.norm(rest(b) - rest(a)))
            else:
                total.append(np.median(np.linalg.norm(src(b) - src(a), axis=-1)))
    return float(np.sum(total) / 2)


def _below_hips(rig: Rig, hips: int) -> np.ndarray:
    flags = np.zeros(len(rig.names), bool)
    for j in rig.order:
        flags[j] = j == hips or (rig.parents[j] >= 0 and flags[rig.parents[j]])
    return flags


def _posed(rig: Rig, delta: np.ndarray, hips_path: np.ndarray) -> np.ndarray:
    """(T, N, 3) world positions: the hips on ``hips_path``, every other node at its parent plus its rest
    offset turned by the parent's delta."""
    rest = rig.rest_world[:, :3, 3]
    hips = rig.bones["hips"]
    out = np.zeros((len(delta), len(rig.names), 3))
    for j in rig.order:
        p = rig.parents[j]
        if j == hips:
            out[:, j] = hips_path
        elif p < 0:
            out[:, j] = rest[j]
        else:
            out[:, j] = out[:, p] + delta[:, p] @ (rest[j] - rest[p])
    return out


def bone_direction_errors(
    rig_positions: np.ndarray, rig_bones: dict[str, int], source: np.ndarray, source_bones: dict[str, int],
    driven: dict[str, tuple[int, int, str]],
) -> dict[str, np.ndarray]:  # fmt: skip
    """Bone -> (T,) angle in degrees between the rig's bone (to its tip) and the source's."""
    out = {}
    for b, (_, _, t) in driven.items():
        a = _unit(rig_positions[:, rig_bones[t]] - rig_positions[:, rig_bones[b]])
        c = _unit(source[:, source_bones[t]] - source[:, source_bones[b]])
        out[b] = np.degrees(np.arccos(np.clip(np.sum(a * c, -1), -1.0, 1.0)))
    return out


def write_gltf_rig(
    rig_path: str | PathLike[str], rig: Rig, result: Retarget, fps: float, out, name: str
) -> Path:
    """The rig's file (meshes, skins, materials and extensions kept) with one animation: a rotation channel
    per driven bone and a translation channel for the hips, one key per frame at ``t = i / fps``; the
    rig's own animations are replaced. ``animation.extras``: ``fps``, ``frames``, ``duration_s``
    (frames / fps). Written atomically to ``out``."""
    from skeleton_mamba.tasks.motion.formats.gltf import (  # lazy: glTF out only
        _Buffer,
        _quaternions_xyzw,
        add_channel,
    )

    gltf = pygltflib.GLTF2().load_binary(str(rig_path))
    blob = bytes(gltf.binary_blob() or b"")
    if not gltf.buffers:
        gltf.buffers.append(pygltflib.Buffer(byteLength=0))
    buffer = _Buffer(gltf)
    buffer.blob = bytearray(blob)
    frames = len(result.hips_translation)
    times = buffer.add(np.arange(frames) / fps, pygltflib.SCALAR, min_max=True)
    animation = pygltflib.Animation(
        name=name, samplers=[], channels=[],
        extras={"fps": float(fps), "frames": frames, "duration_s": frames / float(fps)},
    )  # fmt: skip
    hips = rig.bones["hips"]
    tracks = [(hips, "translation", result.hips_translation)]
    for j, _, _ in result.driven.values():
        if gltf.nodes[j].matrix is not None:
            raise InputError(f"{rig_path}: node {j} ({rig.names[j]}) has a matrix; glTF cannot animate it")
        tracks.append((j, "rotation", _quaternions_xyzw(result.local[j])))
    for node, path, values in tracks:
        output = buffer.add(values, pygltflib.VEC4 if path == "rotation" else pygltflib.VEC3)
        add_channel(animation, times, output, node, path)
    gltf.animations = [animation]
    gltf.buffers[0].byteLength = len(buffer.blob)
    gltf.buffers[0].uri = None
    gltf.set_binary_blob(bytes(buffer.blob))
    data = b"".join(gltf.save_to_bytes())
    out = Path(out)
    with atomic_path(out) as tmp:
        tmp.write_bytes(data)
    return out


def write_bvh_rig(rig: Rig, result: Retarget, fps: float, out) -> Path:
    """A BVH with the rig's hierarchy and offsets (file units): the root's position and every joint's
    rotation (``Zrotation Xrotation Yrotation``, degrees) per frame."""
    from skeleton_mamba.tasks.motion.body.rotations import matrix_to_euler  # lazy: BVH out only
    from skeleton_mamba.tasks.motion.formats.bvh import BvhMotion, save_bvh  # lazy: BVH out only

    bvh = rig.bvh
    root = rig.parents.index(-1)
    frames = len(result.hips_translation)
    hips = rig.bones["hips"]
    columns, channels = [], []
    for j in range(len(rig.names)):
        chs: tuple[str, ...] = ("Zrotation", "Xrotation", "Yrotation")
        if j == root:
            chs = ("Xposition", "Yposition", "Zposition") + chs
            position = (
                result.hips_translation
                if j == hips
                else np.repeat(bvh.offsets[j][None] * rig.metres_per_unit, frames, 0)
            )
            columns.append(position / rig.metres_per_unit)
        rotation = result.local.get(j, np.broadcast_to(np.eye(3), (frames, 3, 3)))  # a BVH rests unturned
        columns.append(np.degrees(matrix_to_euler(rotation, "ZXY")))
        channels.append(chs)
    values = np.concatenate(columns, axis=1)
    offsets = np.asarray(bvh.offsets)
    motion = BvhMotion(
        list(bvh.names), list(bvh.parents), offsets, channels, 1.0 / fps, values, dict(bvh.end_sites)
    )
    return save_bvh(out, motion)
