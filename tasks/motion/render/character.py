"""A character file: a skinned glTF binary or VRM whose own meshes a page draws (``sm view``, ``sm export-web
--rig``), as ``sm retarget`` writes them or as a user's rig comes.

A ``.glb`` / ``.vrm`` is a character when one of its nodes binds a triangle mesh (glTF primitive modes 4, 5,
6, the default 4) to a skin with ``JOINTS_0`` / ``WEIGHTS_0``; the motion glTF that ``sm export`` writes binds
only one point per joint (mode ``POINTS``) and is drawn as a skeleton. The file is read through the toolkit's
bounded glTF reader (:mod:`skeleton_mamba.tasks.motion.formats.gltf_read`: size, magic, JSON) and kept whole,
as the page's GLTFLoader reads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from pathlib import Path

__all__ = ["CHARACTER_SUFFIXES", "Character", "is_character", "read_character", "skinned_triangles"]

CHARACTER_SUFFIXES = (".glb", ".vrm")
_TRIANGLES = (None, 4, 5, 6)  # TRIANGLES (the default), TRIANGLE_STRIP, TRIANGLE_FAN


@dataclass(frozen=True)
class Character:
    """A character file's bytes, its hips node (the humanoid map's, else the skin's first joint) and
    whether it holds an animation (the page plays the first)."""

    data: bytes
    hips: int
    animated: bool


def skinned_triangles(primitive) -> bool:
    """Whether a glTF mesh primitive is triangles (a list, strip or fan) with ``JOINTS_0`` / ``WEIGHTS_0``."""
    a = primitive.attributes
    return primitive.mode in _TRIANGLES and a.JOINTS_0 is not None and a.WEIGHTS_0 is not None


def _skinned_nodes(gltf) -> list:
    """The nodes binding a mesh with a skinned triangle primitive to a skin (both indices in range)."""
    return [
        node
        for node in gltf.nodes
        if node.skin is not None
        and 0 <= node.skin < len(gltf.skins)
        and node.mesh is not None
        and 0 <= node.mesh < len(gltf.meshes)
        and any(skinned_triangles(p) for p in gltf.meshes[node.mesh].primitives)
    ]


def is_character(path: str | PathLike[str]) -> bool:
    """Whether ``path`` is a ``.glb`` / ``.vrm`` with a skinned triangle mesh (module docstring), its file
    read once and its bytes not kept.

    Raises:
        GltfError: a ``.glb`` / ``.vrm`` the bounded reader refuses (naming the file).
    """
    path = Path(path)
    if path.suffix.lower() not in CHARACTER_SUFFIXES:
        return False
    from skeleton_mamba.tasks.motion.formats.gltf_read import _load  # lazy: glTF files only

    return bool(_skinned_nodes(_load(path)[0]))


def read_character(path: str | PathLike[str]) -> Character | None:
    """``path`` as a :class:`Character`, or None where it is not a ``.glb`` / ``.vrm`` with a skinned
    triangle mesh (module docstring).

    Raises:
        GltfError: a ``.glb`` / ``.vrm`` the bounded reader refuses (naming the file).
    """
    path = Path(path)
    if path.suffix.lower() not in CHARACTER_SUFFIXES:
        return None
    from skeleton_mamba.tasks.motion.formats.gltf_read import _load  # lazy: glTF files only

    gltf, _ = _load(path)
    skinned = _skinned_nodes(gltf)
    if not skinned:
        return None
    hips = gltf.skins[skinned[0].skin].joints[0] if gltf.skins[skinned[0].skin].joints else 0
    try:
        from skeleton_mamba.tasks.motion.retarget.rig import load_rig  # lazy: glTF files only

        hips = load_rig(path).bones["hips"]
    except (ValueError, KeyError):  # no humanoid map: the skin's first joint
        pass
    return Character(data=path.read_bytes(), hips=int(hips), animated=bool(gltf.animations))
