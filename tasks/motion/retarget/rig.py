"""Humanoid rigs for ``sm retarget``: a skinned glTF / ``.glb``, a VRM (0.x or 1.0) or a BVH skeleton, and the
map from the humanoid bones (VRM 1.0's names: ``hips``, ``leftUpperArm``, ...) to the rig's nodes.

Bones are found by the VRM humanoid map when the file has one (VRM 0.x ``extensions.VRM.humanoid.humanBones``,
a list of ``{bone, node}``; VRM 1.0 ``extensions.VRMC_vrm.humanoid.humanBones``, bone -> ``{node}``), else by
an explicit map (``--map map.yaml``: bone -> node name), else by the first name preset (:data:`PRESETS`:
Mixamo with or without ``mixamorig:``, VRM / Unity / VRoid, Blender / Rigify, CMU BVH, SMPL, NTU) that names
every required bone (:data:`REQUIRED`). Names compare without case. The same presets find the source motion's
bones.

A rig's rest pose is read as world matrices (T R S of every node, its ancestors' included), so any rest
(T-pose, A-pose, bones rolled about their length, an armature node rotated or scaled) is taken as it is.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

import numpy as np

from skeleton_mamba.errors import InputError

__all__ = ["BONES", "PRESETS", "REQUIRED", "Rig", "find_bones", "load_rig", "read_map", "separate_torso"]

_SIDES = ("left", "right")
_LIMBS = ("Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes")
BONES = ("hips", "spine", "chest", "upperChest", "neck", "head") + tuple(
    s + b for s in _SIDES for b in _LIMBS
)
"""The humanoid bones retargeted (VRM 1.0's names), parents before children."""
REQUIRED = ("hips", "spine", "head") + tuple(
    s + b for s in _SIDES for b in ("UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot")
)
"""The bones a rig and a source must both have (VRM 1.0's required humanoid bones)."""


def _sided(left: dict[str, str], right_of) -> dict[str, str]:
    out = {}
    for bone, name in left.items():
        out[bone] = name
        if bone.startswith("left"):
            out["right" + bone[4:]] = right_of(name)
    return out


def _swap(a: str, b: str):
    return lambda name: name.replace(a, b)


_MIXAMO_LEFT = {
    "hips": "Hips",
    "spine": "Spine",
    "chest": "Spine1",
    "upperChest": "Spine2",
    "neck": "Neck",
    "head": "Head",
    "leftShoulder": "LeftShoulder",
    "leftUpperArm": "LeftArm",
    "leftLowerArm": "LeftForeArm",
    "leftHand": "LeftHand",
    "leftUpperLeg": "LeftUpLeg",
    "leftLowerLeg": "LeftLeg",
    "leftFoot": "LeftFoot",
    "leftToes": "LeftToeBase",
}  # Mixamo's names, the left side; CMU's BVH names are the same without an upper chest

PRESETS: dict[str, dict[str, str]] = {
    "mixamo": _sided(_MIXAMO_LEFT, _swap("Left", "Right")),
    "vrm": _sided({b: b for b in BONES if not b.startswith("right")}, _swap("left", "right")),
    "vroid": _sided(
        {
            "hips": "J_Bip_C_Hips",
            "spine": "J_Bip_C_Spine",
            "chest": "J_Bip_C_Chest",
            "upperChest": "J_Bip_C_UpperChest",
            "neck": "J_Bip_C_Neck",
            "head": "J_Bip_C_Head",
            **{f"left{b}": f"J_Bip_L_{b}" for b in _LIMBS if b != "Toes"},
            "leftToes": "J_Bip_L_ToeBase",
        },
        _swap("_L_", "_R_"),
    ),  # fmt: skip
    "rigify": _sided(
        {
            "hips": "spine",
            "spine": "spine.001",
            "chest": "spine.002",
            "upperChest": "spine.003",
            "neck": "spine.004",
            "head": "spine.006",
            "leftShoulder": "shoulder.L",
            "leftUpperArm": "upper_arm.L",
            "leftLowerArm": "forearm.L",
            "leftHand": "hand.L",
            "leftUpperLeg": "thigh.L",
            "leftLowerLeg": "shin.L",
            "leftFoot": "foot.L",
            "leftToes": "toe.L",
        },
        _swap(".L", ".R"),
    ),  # fmt: skip
    "cmu": _sided({k: v for k, v in _MIXAMO_LEFT.items() if k != "upperChest"}, _swap("Left", "Right")),
    "smpl": _sided(
        {
            "hips": "pelvis",
            "spine": "spine1",
            "chest": "spine2",
            "upperChest": "spine3",
            "neck": "neck",
            "head": "head",
            "leftShoulder": "left_collar",
            "leftUpperArm": "left_shoulder",
            "leftLowerArm": "left_elbow",
            "leftHand": "left_wrist",
            "leftUpperLeg": "left_hip",
            "leftLowerLeg": "left_knee",
            "leftFoot": "left_ankle",
            "leftToes": "left_foot",
        },
        _swap("left", "right"),
    ),  # fmt: skip
    "smpl-capitals": _sided(
        {
            "hips": "Pelvis",
            "spine": "Spine1",
            "chest": "Spine2",
            "upperChest": "Spine3",
            "neck": "Neck",
            "head": "Head",
            "leftShoulder": "L_Collar",
            "leftUpperArm": "L_Shoulder",
            "leftLowerArm": "L_Elbow",
            "leftHand": "L_Wrist",
            "leftUpperLeg": "L_Hip",
            "leftLowerLeg": "L_Knee",
            "leftFoot": "L_Ankle",
            "leftToes": "L_Foot",
        },
        _swap("L_", "R_"),
    ),  # fmt: skip
    "ntu": _sided(
        {
            "hips": "spine_base",
            "spine": "spine_mid",
            "neck": "spine_shoulder",
            "head": "neck",
            "leftUpperArm": "left_shoulder",
            "leftLowerArm": "left_elbow",
            "leftHand": "left_wrist",
            "leftUpperLeg": "left_hip",
            "leftLowerLeg": "left_knee",
            "leftFoot": "left_ankle",
            "leftToes": "left_foot",
        },
        _swap("left", "right"),
    ),  # fmt: skip
}
"""Name presets: humanoid bone -> joint name (compared without case, after :func:`_plain`)."""
# Blender / Rigify deform bones carry a DEF- prefix; Mixamo rigs mixamorig: (or mixamorig1:, ... on reimport).
_PREFIX = re.compile(r"^(mixamorig\d*[:_]|def-|org-)", re.IGNORECASE)


def _plain(name: str) -> str:
    return _PREFIX.sub("", name).lower()


@dataclass
class Rig:
    """A rig's joints at rest.

    Attributes:
        names: N node names.
        parents: N parent indices (-1 for a scene root); parents precede children.
        rest_world: (N, 4, 4) world rest matrices (metres, +Y up).
        bones: humanoid bone -> node index.
        how: how the bones were found (``VRM 1.0 humanoid``, ``preset mixamo``, ``--map FILE``).
        kind: ``gltf`` or ``bvh``.
        order: node indices in the file's order -> our order (``gltf``: node index of each of ours).
        bvh: the BVH the rig came from (``kind == "bvh"``), and its metres per file unit.
    """

    names: list[str]
    parents: list[int]
    rest_world: np.ndarray
    bones: dict[str, int] = field(default_factory=dict)
    how: str = ""
    kind: str = "gltf"
    order: list[int] = field(default_factory=list)
    bvh: object = None
    metres_per_unit: float = 1.0


def _topological(parents: list[int]) -> list[int]:
    order, seen = [], set()

    def visit(j: int) -> None:
        if j in seen:
            return
        if parents[j] >= 0:
            visit(parents[j])
        seen.add(j)
        order.append(j)

    for j in range(len(parents)):
        visit(j)
    return order


def _trs(node) -> np.ndarray:
    if node.matrix is not None:
        return np.asarray(node.matrix, np.float64).reshape(4, 4).T  # column-major
    m = np.eye(4)
    x, y, z, w = node.rotation or [0.0, 0.0, 0.0, 1.0]
    rot = np.array(
        [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    )  # fmt: skip
    m[:3, :3] = rot * np.asarray(node.scale or [1.0, 1.0, 1.0])[None, :]
    m[:3, 3] = node.translation or [0.0, 0.0, 0.0]
    return m


def _vrm_bones(gltf, path: Path) -> tuple[dict[str, int], str] | None:
    ext = gltf.extensions or {}
    if "VRMC_vrm" in ext:
        bones = ((ext["VRMC_vrm"] or {}).get("humanoid") or {}).get("humanBones") or {}
        if not isinstance(bones, dict):
            raise InputError(f"{path}: VRMC_vrm.humanoid.humanBones is not a map of bone -> {{node}}")
        found = {b: v.get("node") for b, v in bones.items() if isinstance(v, dict)}
        how = "VRM 1.0 humanoid"
    elif "VRM" in ext:
        bones = ((ext["VRM"] or {}).get("humanoid") or {}).get("humanBones") or []
        if not isinstance(bones, list):
            raise InputError(f"{path}: VRM.humanoid.humanBones is not a list of {{bone, node}}")
        found = {v.get("bone"): v.get("node") for v in bones if isinstance(v, dict)}
        how = "VRM 0.x humanoid"
    else:
        return None
    out = {}
    for bone, node in found.items():
        if bone in BONES and isinstance(node, int) and 0 <= node < len(gltf.nodes):
            out[bone] = node
    return out, how


def read_map(path: str | PathLike[str]) -> dict[str, str]:
    """A ``--map`` file: YAML mapping humanoid bone (:data:`BONES`) -> the rig's joint name."""
    import yaml  # lazy: only with --map

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such bone map")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file (a bone map is YAML)") from None
    except yaml.YAMLError as err:
        raise InputError(f"{path}: not YAML ({str(err).splitlines()[0]})") from None
    if not isinstance(data, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in data.items()
    ):
        raise InputError(f"{path}: a bone map is YAML lines `bone: joint name` (e.g. `hips: pelvis`)")
    unknown = sorted(set(data) - set(BONES))
    if unknown:
        raise InputError(f"{path}: unknown humanoid bones {', '.join(unknown)} (known: {', '.join(BONES)})")
    return data


def find_bones(
    names: list[str], source: str, explicit: dict[str, str] | None = None, what: str = "rig"
) -> tuple[dict[str, int], str]:
    """Humanoid bone -> joint index for joint ``names``, by ``explicit`` (a ``--map``) else the first preset
    naming every :data:`REQUIRED` bone; else :class:`InputError` naming ``source`` and the missing bones."""
    index: dict[str, int] = {}
    for j, n in enumerate(names):
        index.setdefault(_plain(n), j)
        index.setdefault(n.lower(), j)
    if explicit is not None:
        absent = [n for n in explicit.values() if n.lower() not in index and _plain(n) not in index]
        if absent:
            raise InputError(f"{source}: the bone map names joints the {what} lacks: {', '.join(absent)}")
        bones = {b: index.get(n.lower(), index.get(_plain(n))) for b, n in explicit.items()}
        missing = [b for b in REQUIRED if b not in bones]
        if missing:
            raise InputError(f"{source}: the bone map lacks the required bones {', '.join(missing)}")
        return bones, "--map"
    best: tuple[list[str], str] | None = None
    for preset, table in PRESETS.items():
        bones = {b: index[_plain(n)] for b, n in table.items() if _plain(n) in index}
        missing = [b for b in REQUIRED if b not in bones]
        if not missing:
            return bones, f"preset {preset}"
        if best is None or len(missing) < len(best[0]):
            best = (missing, preset)
    assert best is not None
    raise InputError(f"{source}: the {what} lacks the humanoid bones {', '.join(best[0])} (closest preset: "
                     f"{best[1]}; presets tried: {', '.join(PRESETS)}); pass --map map.yaml")  # fmt: skip


def load_rig(path: str | PathLike[str], explicit: dict[str, str] | None = None) -> Rig:
    """A rig from a ``.glb`` / ``.vrm`` (every node of the file) or a ``.bvh`` (its joints, in metres)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such rig file")
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return _bvh_rig(path, explicit)
    if suffix not in (".glb", ".vrm"):
        raise InputError(f"{path}: a rig is a .glb, .vrm or .bvh file")
    from skeleton_mamba.tasks.motion.formats.gltf_read import _load  # lazy: a glTF rig only

    try:
        gltf, _ = _load(path)
    except FileNotFoundError:
        raise
    except ValueError as err:
        raise InputError(str(err)) from None
    if not gltf.skins and suffix != ".bvh":
        raise InputError(f"{path}: holds no skin: not a skinned character")
    n = len(gltf.nodes)
    parents = [-1] * n
    for p, node in enumerate(gltf.nodes):
        for c in node.children or []:
            if not isinstance(c, int) or not 0 <= c < n or parents[c] != -1:
                raise InputError(f"{path}: node {p} has a bad or shared child {c!r}")
            parents[c] = p
    try:
        order = _topological(parents)
    except RecursionError:
        raise InputError(f"{path}: the node tree has a cycle") from None
    world = np.zeros((n, 4, 4))
    for j in order:
        local = _trs(gltf.nodes[j])
        world[j] = local if parents[j] < 0 else world[parents[j]] @ local
    names = [node.name or f"node{j}" for j, node in enumerate(gltf.nodes)]
    vrm = _vrm_bones(gltf, path)
    if vrm is not None and explicit is None:
        bones, how = vrm
        missing = [b for b in REQUIRED if b not in bones]
        if missing:
            raise InputError(f"{path}: the {how} map lacks the humanoid bones {', '.join(missing)}")
    else:
        bones, how = find_bones(names, str(path), explicit)
    for j in bones.values():
        k = j
        while k >= 0:  # the bone and its ancestors: rotations are read from their world matrices
            stretch = np.linalg.svd(world[k, :3, :3], compute_uv=False)
            if stretch.min() < 1e-8 or stretch.max() > stretch.min() * (1 + 1e-3):
                raise InputError(f"{path}: node {k} ({names[k]}) is scaled unevenly or to zero at rest; "
                                 "apply its scale in your editor first")  # fmt: skip
            k = parents[k]
    return Rig(names, parents, world, bones, how, "gltf", order)


def _bvh_rig(path: Path, explicit: dict[str, str] | None) -> Rig:
    from skeleton_mamba.tasks.motion.formats.bvh import load_bvh  # lazy: a BVH rig only
    from skeleton_mamba.tasks.motion.formats.units import choose_scale  # lazy: a BVH rig only

    bvh = load_bvh(path)
    scale = choose_scale(None, None, bvh.rest_height()).metres_per_unit
    n = len(bvh.names)
    world = np.zeros((n, 4, 4))
    world[:] = np.eye(4)
    for j, p in enumerate(bvh.parents):
        world[j, :3, 3] = (world[p, :3, 3] if p >= 0 else 0.0) + np.asarray(bvh.offsets[j]) * scale
    bones, how = find_bones(list(bvh.names), str(path), explicit)
    return Rig(list(bvh.names), list(bvh.parents), world, bones, how, "bvh", list(range(n)), bvh, scale)


def separate_torso(bones: dict[str, int], parents: list[int], positions: np.ndarray) -> dict[str, int]:
    """``bones`` of a source with a torso bone (``spine`` to ``neck``) that sits on the torso bone below it
    (CMU's ``Neck`` on ``Spine1``) moved down to its only child (``Neck1``), so every torso bone has a
    direction. ``positions``: (T, J, 3) the source's joints."""
    out = dict(bones)
    children: dict[int, list[int]] = {}
    for j, p in enumerate(parents):
        children.setdefault(p, []).append(j)
    below = None
    for b in ("hips", "spine", "chest", "upperChest", "neck"):
        if b not in out:
            continue
        j = out[b]
        while below is not None and np.linalg.norm(positions[0, j] - positions[0, below]) < 1e-4:
            if len(children.get(j, [])) != 1:
                break
            j = children[j][0]
        out[b] = below = j
    return out
