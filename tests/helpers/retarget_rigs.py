"""Humanoid rigs built in code for the retarget tests, and an independent glTF forward kinematics (pygltflib
and numpy only, sharing no code with :mod:`skeleton_mamba.tasks.motion.retarget.transfer`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib
from scipy.spatial.transform import Rotation

# bone -> (parent, rest position of a 1.0 m-leg T-pose figure facing +Z, its left on +X)
_T_POSE = {
    "hips": (None, (0.0, 1.0, 0.0)),
    "spine": ("hips", (0.0, 1.1, -0.01)),
    "chest": ("spine", (0.0, 1.25, 0.0)),
    "neck": ("chest", (0.0, 1.45, 0.0)),
    "head": ("neck", (0.0, 1.55, 0.02)),
    "leftShoulder": ("chest", (0.05, 1.40, 0.0)),
    "leftUpperArm": ("leftShoulder", (0.18, 1.40, 0.0)),
    "leftLowerArm": ("leftUpperArm", (0.45, 1.40, 0.0)),
    "leftHand": ("leftLowerArm", (0.70, 1.40, 0.0)),
    "leftUpperLeg": ("hips", (0.09, 0.95, 0.0)),
    "leftLowerLeg": ("leftUpperLeg", (0.09, 0.52, 0.01)),
    "leftFoot": ("leftLowerLeg", (0.09, 0.08, 0.0)),
    "leftToes": ("leftFoot", (0.09, 0.0, 0.12)),
}
HUMANOID = list(_T_POSE) + [b.replace("left", "right") for b in _T_POSE if b.startswith("left")]
MIXAMO = {
    "hips": "Hips", "spine": "Spine", "chest": "Spine1", "neck": "Neck", "head": "Head",
    "leftShoulder": "LeftShoulder", "leftUpperArm": "LeftArm", "leftLowerArm": "LeftForeArm",
    "leftHand": "LeftHand",
    "leftUpperLeg": "LeftUpLeg", "leftLowerLeg": "LeftLeg", "leftFoot": "LeftFoot", "leftToes": "LeftToeBase",
}  # fmt: skip
MIXAMO.update({b.replace("left", "right"): n.replace("Left", "Right") for b, n in list(MIXAMO.items())})
SMPL = {
    "hips": "pelvis", "spine": "spine1", "chest": "spine2", "neck": "neck", "head": "head",
    "leftShoulder": "left_collar", "leftUpperArm": "left_shoulder", "leftLowerArm": "left_elbow",
    "leftHand": "left_wrist", "leftUpperLeg": "left_hip", "leftLowerLeg": "left_knee",
    "leftFoot": "left_ankle", "leftToes": "left_foot",
}  # fmt: skip
SMPL.update({b.replace("left", "right"): n.replace("left", "right") for b, n in list(SMPL.items())})
# (bone, tip) pairs whose directions are compared
PAIRS = [("hips", "spine"), ("spine", "chest"), ("chest", "neck"), ("neck", "head")] + [
    (s + a, s + b)
    for s in ("left", "right")
    for a, b in [("Shoulder", "UpperArm"), ("UpperArm", "LowerArm"), ("LowerArm", "Hand"),
                 ("UpperLeg", "LowerLeg"), ("LowerLeg", "Foot"), ("Foot", "Toes")]
]  # fmt: skip


def rest_positions(scale: float = 1.0, a_pose: bool = False, legs: float = 1.0) -> dict[str, np.ndarray]:
    """Bone -> world rest position; ``a_pose`` turns the arms 45 degrees down; ``legs`` stretches the legs."""
    out: dict[str, np.ndarray] = {}
    for b in HUMANOID:
        left = b.replace("right", "left")
        p = np.array(_T_POSE[left][1], np.float64)
        if b.startswith("right"):
            p[0] = -p[0]
        out[b] = p
    lift = 1.0 * (legs - 1.0)
    for b in out:
        if "Leg" in b or "Foot" in b or "Toes" in b:
            out[b][1] *= legs
        else:
            out[b][1] += lift
    if a_pose:
        for s, sign in (("left", 1.0), ("right", -1.0)):
            shoulder = out[f"{s}UpperArm"]
            turn = Rotation.from_euler("z", -sign * 45, degrees=True).as_matrix()
            for b in ("LowerArm", "Hand"):
                out[s + b] = shoulder + turn @ (out[s + b] - shoulder)
    return {b: p * scale for b, p in out.items()}


def parent_of(bone: str) -> str | None:
    parent = _T_POSE[bone.replace("right", "left")][0]
    return None if parent is None else parent.replace("left", "right") if bone.startswith("right") else parent


def build_rig(
    path: Path, names: dict[str, str], positions: dict[str, np.ndarray], roll_seed: int | None = None,
    armature_scale: float = 1.0, vrm: str | None = None,
) -> Path:  # fmt: skip
    """A skinned .glb/.vrm: an ``Armature`` node (uniform ``armature_scale``, turned 0 degrees), the bones
    (world rest rotations random when ``roll_seed``: rolled, tilted rests), one box per bone skinned to it;
    ``vrm``: ``"0"`` or ``"1"`` adds that VRM humanoid map."""
    rng = np.random.default_rng(roll_seed)
    bones = list(positions)
    world_rot = {
        b: (Rotation.random(random_state=rng).as_matrix() if roll_seed is not None else np.eye(3))
        for b in bones
    }
    gltf = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"))
    arm = pygltflib.Node(name="Armature", scale=[armature_scale] * 3, children=[])
    gltf.nodes.append(arm)
    index = {b: i + 1 for i, b in enumerate(bones)}
    inv_scale = 1.0 / armature_scale
    world_mats = {}
    for b in bones:
        p = parent_of(b)
        local_r = world_rot[b] if p is None else world_rot[p].T @ world_rot[b]
        delta = positions[b] if p is None else world_rot[p].T @ (positions[b] - positions[p])
        x, y, z, w = Rotation.from_matrix(local_r).as_quat()
        node = pygltflib.Node(name=names[b], translation=[float(v) for v in delta * inv_scale],
                              rotation=[float(x), float(y), float(z), float(w)], children=[])  # fmt: skip
        gltf.nodes.append(node)
        m = np.eye(4)
        m[:3, :3] = world_rot[b] * armature_scale
        m[:3, 3] = positions[b]
        world_mats[b] = m
    for b in bones:
        p = parent_of(b)
        (arm.children if p is None else gltf.nodes[index[p]].children).append(index[b])
    # one box per bone, around its joint, weighted wholly to it
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float32) * 0.03
    verts = np.concatenate([corners + positions[b] for b in bones]).astype(np.float32)
    joints = np.repeat(np.arange(len(bones)), 8)[:, None] * np.array([1, 0, 0, 0])
    weights = np.tile([1.0, 0.0, 0.0, 0.0], (len(verts), 1)).astype(np.float32)
    faces = []
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    for k in range(len(bones)):
        for a, b_, c, d in quads:
            faces += [(a + 8 * k, b_ + 8 * k, c + 8 * k), (a + 8 * k, c + 8 * k, d + 8 * k)]
    inv_bind = np.stack([np.linalg.inv(world_mats[b]).T for b in bones]).astype(np.float32)
    blob = bytearray()

    def add(array, kind, ctype, target=None, minmax=False):
        data = np.ascontiguousarray(array)
        blob.extend(b"\0" * (-len(blob) % 4))
        gltf.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=data.nbytes,
                                                     target=target))  # fmt: skip
        blob.extend(data.tobytes())
        acc = pygltflib.Accessor(bufferView=len(gltf.bufferViews) - 1, componentType=ctype, count=len(data),
                                 type=kind)  # fmt: skip
        if minmax:
            acc.min = data.reshape(len(data), -1).min(0).tolist()
            acc.max = data.reshape(len(data), -1).max(0).tolist()
        gltf.accessors.append(acc)
        return len(gltf.accessors) - 1

    attrs = pygltflib.Attributes(
        POSITION=add(verts, "VEC3", pygltflib.FLOAT, pygltflib.ARRAY_BUFFER, True),
        JOINTS_0=add(joints.astype(np.uint16), "VEC4", pygltflib.UNSIGNED_SHORT, pygltflib.ARRAY_BUFFER),
        WEIGHTS_0=add(weights, "VEC4", pygltflib.FLOAT, pygltflib.ARRAY_BUFFER),
    )
    indices = add(np.asarray(faces, np.uint16).reshape(-1), "SCALAR", pygltflib.UNSIGNED_SHORT,
                  pygltflib.ELEMENT_ARRAY_BUFFER)  # fmt: skip
    gltf.meshes.append(
        pygltflib.Mesh(name="body", primitives=[pygltflib.Primitive(attributes=attrs, indices=indices)])
    )
    gltf.skins.append(pygltflib.Skin(joints=[index[b] for b in bones], inverseBindMatrices=add(
        inv_bind.reshape(-1, 16), "MAT4", pygltflib.FLOAT)))  # fmt: skip
    gltf.nodes.append(pygltflib.Node(name="body", mesh=0, skin=0))
    gltf.scenes.append(pygltflib.Scene(nodes=[0, len(gltf.nodes) - 1]))
    gltf.scene = 0
    if vrm == "1":
        gltf.extensionsUsed = ["VRMC_vrm"]
        meta = {
            "name": "test rig",
            "authors": ["skeleton-mamba tests"],
            "licenseUrl": "https://vrm.dev/licenses/1.0/",
        }  # VRM 1.0's required meta
        gltf.extensions = {"VRMC_vrm": {"specVersion": "1.0", "meta": meta, "humanoid": {
            "humanBones": {b: {"node": index[b]} for b in bones}}}}  # fmt: skip
    elif vrm == "0":
        gltf.extensionsUsed = ["VRM"]
        gltf.extensions = {
            "VRM": {"meta": {"title": "test rig", "author": "skeleton-mamba tests"},
                    "humanoid": {"humanBones": [{"bone": b, "node": index[b]} for b in bones]}}
        }  # fmt: skip
    gltf.buffers.append(pygltflib.Buffer(byteLength=len(blob)))
    gltf.set_binary_blob(bytes(blob))
    path.write_bytes(b"".join(gltf.save_to_bytes()))
    return path


def _accessor(gltf, blob, index):
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc.type]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    return (
        np.frombuffer(blob, np.float32, acc.count * width, start).reshape(acc.count, width).astype(np.float64)
    )


def read_animated(path: Path) -> tuple[pygltflib.GLTF2, np.ndarray, np.ndarray, np.ndarray]:
    """(gltf, key times (T,), world matrices (T, N, 4, 4) of every node, local rotations (T, N, 3, 3)) of the
    first animation, by the glTF rule world = parent @ T R S."""
    gltf = pygltflib.GLTF2().load_binary(str(path))
    blob = gltf.binary_blob()
    anim = gltf.animations[0]
    times = _accessor(gltf, blob, anim.samplers[0].input)[:, 0]
    frames, n = len(times), len(gltf.nodes)
    t = np.array([nd.translation or [0.0, 0.0, 0.0] for nd in gltf.nodes], np.float64)[None].repeat(frames, 0)
    q = np.array([nd.rotation or [0.0, 0.0, 0.0, 1.0] for nd in gltf.nodes], np.float64)[None].repeat(
        frames, 0
    )
    s = np.array([nd.scale or [1.0, 1.0, 1.0] for nd in gltf.nodes], np.float64)
    for ch in anim.channels:
        sampler = anim.samplers[ch.sampler]
        assert np.array_equal(_accessor(gltf, blob, sampler.input)[:, 0], times)
        (t if ch.target.path == "translation" else q)[:, ch.target.node] = _accessor(
            gltf, blob, sampler.output
        )
    rot = Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(frames, n, 3, 3)
    local = np.zeros((frames, n, 4, 4))
    local[..., :3, :3] = rot * s[None, :, None, :]
    local[..., :3, 3] = t
    local[..., 3, 3] = 1.0
    parent = {c: p for p, nd in enumerate(gltf.nodes) for c in nd.children or []}
    world: dict[int, np.ndarray] = {}

    def world_of(j: int) -> np.ndarray:
        if j not in world:
            world[j] = world_of(parent[j]) @ local[:, j] if j in parent else local[:, j]
        return world[j]

    return gltf, times, np.stack([world_of(j) for j in range(n)], 1), rot
