"""Motions as glTF 2.0 binary files (``.glb``): a skinned skeleton with one animation, written with pygltflib.

Every motion the toolkit reads (:func:`~.motion_reader.load_skeleton_motion`) becomes a
:class:`SkeletonMotion`: a joint tree (names, parents), its rest offsets and per-frame local transforms.
The glTF file holds:

- one node per joint, named as the skeleton's joint, children under their parent (several roots allowed,
  e.g. the two bodies of an NTU file); node translation = rest offset, metres, +Y up (glTF's axes);
- one skin listing the joints with their inverse bind matrices (inverse world rest transforms), so a
  mesh can be bound to it by any tool;
- one animation, linear interpolation, one key per frame at ``t = i / fps``: a ``rotation`` channel
  (unit quaternion, x y z w) per joint and a ``translation`` channel for the root when the source has
  rotations (SMPL poses, BVH); a ``translation`` channel per joint when it has only joint positions
  (then a joint's translation is its position minus its parent's, parents unrotated);
- ``asset.extras``: ``fps``, ``units`` (``metres``) and the scale the reader applied to the source
  (``metres_per_source_unit``, ``source_units``: how it was chosen, :mod:`.units`).

A node's world transform is its parent's times ``T(translation) R(rotation)``, the glTF rule, which is the
toolkit's forward kinematics (:mod:`skeleton_mamba.tasks.motion.body.kinematics`), so the file reproduces the
source's joint positions.

Before anything is written a motion is checked (:func:`check_skeleton_motion`, naming the source file): at
least one frame, a frame rate in :data:`~skeleton_mamba.tasks.motion.io.option_types.FPS_RANGE`, key times
that still increase once stored as float32, at most :data:`MAX_JOINTS` joints (``JOINTS_0`` may only be
``UNSIGNED_BYTE`` or ``UNSIGNED_SHORT`` in glTF 2.0, so more joints cannot be bound), and finite offsets,
translations and rotations within :data:`~skeleton_mamba.tasks.motion.io.value_checks.MAX_POSITION_M`.

:mod:`.gltf_read` reads such a file back.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
import pygltflib
import torch

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.atomic import atomic_path
from skeleton_mamba.skeletons import get_skeleton, parents_first_order
from skeleton_mamba.tasks.motion.body.kinematics import forward_kinematics
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix, matrix_to_quaternion
from skeleton_mamba.tasks.motion.body.smpl import SMPL_REST_OFFSETS
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.motion.formats.units import METRES, UnitScale
from skeleton_mamba.tasks.motion.io.value_checks import (
    MAX_POSITION_M,
    check_finite,
    check_fps,
    check_magnitude,
)

__all__ = [
    "add_channel",
    "MAX_JOINTS",
    "SkeletonMotion",
    "check_skeleton_motion",
    "from_motion_data",
    "from_joints",
    "glb_bytes",
    "write_glb",
]

MAX_JOINTS = 65_535  # JOINTS_0 as UNSIGNED_SHORT, the widest component type glTF 2.0 allows for it


@dataclass
class SkeletonMotion:
    """A joint tree and its motion, ready for glTF.

    Attributes:
        names: J joint names.
        parents: J parent indices, ``-1`` for a root.
        fps: frames per second.
        offsets: (J, 3) rest offsets from the parent (a root's: its rest position), metres.
        translations: (T, J, 3) per-frame local translations (rest offsets where a joint has no channel).
        rotations: (T, J, 3, 3) local rotations, or None for a positions-only motion.
        translated: J flags, True where the joint has an animated translation channel.
        scale: the metres per unit the reader applied (:mod:`.units`), stated in the written file.
    """

    names: list[str]
    parents: list[int]
    fps: float
    offsets: np.ndarray
    translations: np.ndarray
    rotations: np.ndarray | None
    translated: list[bool]
    scale: UnitScale = METRES

    @property
    def num_frames(self) -> int:
        return len(self.translations)

    def joint_positions(self) -> np.ndarray:
        """(T, J, 3) world positions by the glTF rule ``world = parent @ T(translation) R(rotation)``.

        Forward kinematics (:mod:`skeleton_mamba.tasks.motion.body.kinematics`) under a virtual root at the
        origin, so that every root (several for two bodies) sits at its own translation.
        """
        t = torch.from_numpy(np.asarray(self.translations, np.float64))
        frames, joints = t.shape[:2]
        eye = torch.eye(3, dtype=torch.float64).expand(frames, 1, 3, 3)
        if self.rotations is None:
            rotations = eye.expand(frames, joints, 3, 3)
        else:
            rotations = torch.from_numpy(np.asarray(self.rotations, np.float64))
        parents = [-1] + [p + 1 if p >= 0 else 0 for p in self.parents]
        order = parents_first_order(parents, "motion")
        positions, _ = forward_kinematics(
            torch.cat([eye, rotations], dim=1),
            torch.zeros(frames, 3, dtype=torch.float64),
            torch.cat([torch.zeros(frames, 1, 3, dtype=torch.float64), t], dim=1),
            parents,
            order,
        )
        return positions[:, 1:].numpy()


def from_motion_data(motion: MotionData) -> SkeletonMotion:
    """Our :class:`MotionData`: SMPL rotations + root translation when it has poses, else its joints."""
    if motion.poses is None:
        return from_joints(np.asarray(motion.joints, np.float64), motion.skeleton, motion.fps)
    skel = get_skeleton("smpl24")
    offsets = np.asarray(SMPL_REST_OFFSETS, np.float64)
    rotations = axis_angle_to_matrix(torch.from_numpy(np.asarray(motion.poses, np.float64))).numpy()
    translations = np.repeat(offsets[None], motion.num_frames, axis=0)
    translations[:, 0] = motion.root_position()
    flags = [p < 0 for p in skel.parents]
    return SkeletonMotion(
        list(skel.joint_names), list(skel.parents), motion.fps, offsets, translations, rotations, flags
    )


def from_joints(
    joints: np.ndarray,
    skeleton: str | None,
    fps: float,
    parents: list[int] | None = None,
    names: list[str] | None = None,
) -> SkeletonMotion:
    """Joint positions (T, J, 3) of ``skeleton`` (or of ``parents`` / ``names``) as translation channels."""
    if parents is None:
        skel = get_skeleton(skeleton)
        parents, names = list(skel.parents), list(skel.joint_names)
    joints = np.asarray(joints, np.float64)
    parent_positions = np.where(
        (np.asarray(parents) >= 0)[None, :, None], joints[:, np.maximum(parents, 0)], 0.0
    )
    translations = joints - parent_positions
    return SkeletonMotion(
        list(names), list(parents), fps, translations[0].copy(), translations, None, [True] * len(parents)
    )


def check_skeleton_motion(motion: SkeletonMotion, source: str) -> SkeletonMotion:
    """``motion`` when glTF can hold it (module docstring), else :class:`InputError` naming ``source``."""
    frames, joints = motion.num_frames, len(motion.names)
    if frames < 1:
        raise InputError(f"{source}: the motion has no frames")
    if not 1 <= joints <= MAX_JOINTS:
        raise InputError(
            f"{source}: {joints:,} joints; a glTF skin binds 1 to {MAX_JOINTS:,} (16-bit JOINTS_0 indices)"
        )
    try:
        check_fps(float(motion.fps), "frame rate")
    except ValueError as err:
        raise InputError(f"{source}: {err}") from None
    times = (np.arange(frames) / motion.fps).astype(np.float32)
    if frames > 1 and not np.all(np.diff(times) > 0):
        raise InputError(f"{source}: {frames:,} frames at {motion.fps:g} fps: the key times stop increasing "
                         "in float32 (glTF's time type); split the motion")  # fmt: skip
    arrays = [
        ("offsets", motion.offsets, ("joint",)),
        ("translations", motion.translations, ("frame", "joint")),
    ]
    for what, array, axes in arrays:
        check_finite(np.asarray(array), source, what, axes, InputError)
        check_magnitude(np.asarray(array), MAX_POSITION_M, source, what, axes, InputError)
    if motion.rotations is not None:
        check_finite(np.asarray(motion.rotations), source, "rotations", ("frame", "joint"), InputError)
    return motion


def _quaternions_xyzw(rotations: np.ndarray) -> np.ndarray:
    wxyz = matrix_to_quaternion(torch.from_numpy(np.ascontiguousarray(rotations, np.float64))).numpy()
    xyzw = np.concatenate([wxyz[..., 1:], wxyz[..., :1]], axis=-1)
    xyzw /= np.linalg.norm(xyzw, axis=-1, keepdims=True)
    # The same sign from key to key, so linear interpolation takes the short way.
    for t in range(1, len(xyzw)):
        flip = np.sum(xyzw[t] * xyzw[t - 1], axis=-1) < 0
        xyzw[t, flip] *= -1
    return xyzw


def _rest_world(motion: SkeletonMotion) -> np.ndarray:
    """(J, 4, 4) world rest matrices (translation only: the rest pose has identity rotations)."""
    world = np.zeros((len(motion.names), 4, 4))
    world[:] = np.eye(4)
    done = [False] * len(motion.names)

    def visit(j: int) -> np.ndarray:
        if not done[j]:
            p = motion.parents[j]
            base = visit(p)[:3, 3] if p >= 0 else np.zeros(3)
            world[j, :3, 3] = base + motion.offsets[j]
            done[j] = True
        return world[j]

    for j in range(len(motion.names)):
        visit(j)
    return world


def add_channel(animation: pygltflib.Animation, times: int, values: int, node: int, path: str) -> None:
    """Animate ``node``'s ``path`` (``"rotation"``, ``"translation"``) in ``animation``: a linear sampler
    from the key-time accessor ``times`` to the value accessor ``values``, and its channel."""
    animation.samplers.append(pygltflib.AnimationSampler(input=times, output=values, interpolation="LINEAR"))
    animation.channels.append(
        pygltflib.AnimationChannel(
            sampler=len(animation.samplers) - 1, target=pygltflib.AnimationChannelTarget(node=node, path=path)
        )
    )


class _Buffer:
    """Accessors packed into one binary buffer, each 4-byte aligned."""

    def __init__(self, gltf: pygltflib.GLTF2):
        self.gltf = gltf
        self.blob = bytearray()

    def add(self, array: np.ndarray, kind: str, min_max: bool = False, target: int | None = None) -> int:
        integer = np.issubdtype(np.asarray(array).dtype, np.integer)
        if (
            integer
            and np.asarray(array).size
            and not 0 <= np.asarray(array).min() <= np.max(array) <= MAX_JOINTS
        ):
            raise ValueError(f"joint indices beyond UNSIGNED_SHORT (0 to {MAX_JOINTS}) cannot be stored")
        data = np.ascontiguousarray(array, np.uint16 if integer else np.float32)
        self.blob += b"\0" * (-len(self.blob) % 4)
        self.gltf.bufferViews.append(
            pygltflib.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=data.nbytes, target=target)
        )
        self.blob += data.tobytes()
        flat = data.reshape(len(data), -1)
        accessor = pygltflib.Accessor(
            bufferView=len(self.gltf.bufferViews) - 1,
            componentType=pygltflib.UNSIGNED_SHORT if integer else pygltflib.FLOAT,
            count=len(data),
            type=kind,
        )
        if min_max:
            accessor.min = [float(v) for v in flat.min(axis=0)]
            accessor.max = [float(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1


def write_glb(motion: SkeletonMotion, out: str | PathLike[str], name: str = "motion") -> Path:
    """Write ``motion`` as a ``.glb`` (module docstring for the layout), atomically; returns the path.

    Raises:
        InputError: a motion glTF cannot hold (:func:`check_skeleton_motion`), naming ``out``.
    """
    out = Path(out)
    data = glb_bytes(motion, name, str(out))
    with atomic_path(out) as tmp:
        tmp.write_bytes(data)
    return out


def glb_bytes(motion: SkeletonMotion, name: str = "motion", source: str = "motion") -> bytes:
    """``motion`` as the bytes of a ``.glb`` (module docstring), checked first (:func:`check_skeleton_motion`,
    errors naming ``source``)."""
    check_skeleton_motion(motion, source)
    num_joints = len(motion.names)
    extras = {
        "fps": float(motion.fps),
        "units": "metres",
        "metres_per_source_unit": motion.scale.metres_per_unit,
        "source_units": motion.scale.note,
    }
    asset = pygltflib.Asset(version="2.0", generator="skeleton-mamba", extras=extras)
    gltf = pygltflib.GLTF2(asset=asset)
    buffer = _Buffer(gltf)
    rotations = None if motion.rotations is None else _quaternions_xyzw(motion.rotations)
    children: list[list[int]] = [[] for _ in range(num_joints)]
    for j, p in enumerate(motion.parents):
        if p >= 0:
            children[p].append(j)
    for j in range(num_joints):
        node = pygltflib.Node(name=motion.names[j], translation=[float(v) for v in motion.offsets[j]])
        if children[j]:
            node.children = children[j]
        gltf.nodes.append(node)
    roots = [j for j, p in enumerate(motion.parents) if p < 0]
    inverse_bind = np.linalg.inv(_rest_world(motion)).transpose(0, 2, 1)  # column-major
    gltf.skins.append(
        pygltflib.Skin(
            name=name,
            joints=list(range(num_joints)),
            skeleton=roots[0] if len(roots) == 1 else None,
            inverseBindMatrices=buffer.add(inverse_bind.reshape(num_joints, 16), pygltflib.MAT4),
        )
    )
    # The skinned mesh: one point per joint at its rest position, bound wholly to that joint.
    rest = _rest_world(motion)[:, :3, 3]
    bones = np.zeros((num_joints, 4), np.int64)
    bones[:, 0] = np.arange(num_joints)
    weights = np.zeros((num_joints, 4))
    weights[:, 0] = 1.0
    attributes = pygltflib.Attributes(
        POSITION=buffer.add(rest, pygltflib.VEC3, min_max=True, target=pygltflib.ARRAY_BUFFER),
        JOINTS_0=buffer.add(bones, pygltflib.VEC4, target=pygltflib.ARRAY_BUFFER),
        WEIGHTS_0=buffer.add(weights, pygltflib.VEC4, target=pygltflib.ARRAY_BUFFER),
    )
    primitive = pygltflib.Primitive(attributes=attributes, mode=pygltflib.POINTS)
    gltf.meshes.append(pygltflib.Mesh(name=f"{name}_joints", primitives=[primitive]))
    gltf.nodes.append(pygltflib.Node(name=f"{name}_joints", mesh=0, skin=0))
    gltf.scenes.append(pygltflib.Scene(name=name, nodes=[*roots, num_joints]))
    gltf.scene = 0

    times = buffer.add(np.arange(motion.num_frames) / motion.fps, pygltflib.SCALAR, min_max=True)
    animation = pygltflib.Animation(name=name, samplers=[], channels=[])
    for j in range(num_joints):
        tracks = []
        if motion.translated[j]:
            tracks.append(("translation", buffer.add(motion.translations[:, j], pygltflib.VEC3)))
        if rotations is not None:
            tracks.append(("rotation", buffer.add(rotations[:, j], pygltflib.VEC4)))
        for path, accessor in tracks:
            add_channel(animation, times, accessor, j, path)
    gltf.animations.append(animation)
    gltf.buffers.append(pygltflib.Buffer(byteLength=len(buffer.blob)))
    gltf.set_binary_blob(bytes(buffer.blob))
    try:
        return b"".join(gltf.save_to_bytes())
    except ValueError as err:  # pygltflib's strict JSON: a value the checks above let through
        raise InputError(f"{source}: cannot be written as glTF ({err})") from err
