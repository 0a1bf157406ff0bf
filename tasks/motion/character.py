"""A character file: a skinned glTF binary or VRM whose own meshes a page draws (``sm view``, ``sm export-web
--rig``), as ``sm retarget`` writes them or as a user's rig comes.

A ``.glb`` / ``.vrm`` is a character when one of its nodes binds a triangle mesh (glTF primitive modes 4, 5,
6, the default 4) to a skin with ``JOINTS_0`` / ``WEIGHTS_0``; the motion glTF that ``sm export`` writes binds
only one point per joint (mode ``POINTS``) and is drawn as a skeleton. The file is read through the toolkit's
bounded glTF reader (:mod:`.gltf_read`: size, magic, JSON) and kept whole, as the page's GLTFLoader reads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from pathlib import Path

__all__ = ["CHARACTER_SUFFIXES", "Character", "read_character"]

CHARACTER_SUFFIXES = (".glb", ".vrm")
_TRIANGLES = (None, 4, 5, 6)  # TRIANGLES (the default), TRIANGLE_STRIP, TRIANGLE_FAN


@dataclass(frozen=True)
class Character:
    """A character file's bytes, its hips node (the humanoid map's, else the skin's first joint) and
    whether it holds an animation (the page plays the first)."""

    data: bytes
    hips: int
    animated: bool


def read_character(path: str | PathLike[str]) -> Character | None:
    """``path`` as a :class:`Character`, or None where it is not a ``.glb`` / ``.vrm`` with a skinned
    triangle mesh (module docstring).

    Raises:
        GltfError: a ``.glb`` / ``.vrm`` the bounded reader refuses (naming the file).
    """
    path = Path(path)
    if path.suffix.lower() not in CHARACTER_SUFFIXES:
        return None
    from skeleton_mamba.tasks.motion.gltf_read import _load  # lazy: glTF files only

    gltf, _ = _load(path)
    skinned = [
        node
        for node in gltf.nodes
        if node.skin is not None
        and 0 <= node.skin < len(gltf.skins)
        and node.mesh is not None
        and 0 <= node.mesh < len(gltf.meshes)
    ]
    if not any(
        p.mode in _TRIANGLES and p.attributes.JOINTS_0 is not None and p.attributes.WEIGHTS_0 is not None
        for node in skinned
        for p in gltf.meshes[node.mesh].primitives
    ):
        return None
    hips = gltf.skins[skinned[0].skin].joints[0] if gltf.skins[skinned[0].skin].joints else 0
    try:
        from skeleton_mamba.tasks.motion.retarget_rig import load_rig  # lazy: glTF files only

        hips = load_rig(path).bones["hips"]
    except (ValueError, KeyError):  # no humanoid map: the skin's first joint
        pass
    return Character(data=path.read_bytes(), hips=int(hips), animated=bool(gltf.animations))
