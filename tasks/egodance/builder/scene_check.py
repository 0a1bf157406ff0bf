"""Scene files checked before they are loaded or ray cast: a stated bound on their triangles.

A scene is loaded whole, then ray cast at every frame; its memory and time grow with its triangles. So
:func:`check_scene_file` counts the triangles a file declares before trimesh loads it, from what each
format states up front, and refuses more than ``max_faces`` (default :data:`MAX_SCENE_FACES`; ``sm make-ego
--max-faces`` raises it):

- ``.ply``: the ``element face N`` (and ``element vertex N``) lines of its header;
- ``.glb`` / ``.gltf``: the JSON (read by the project's bounded reader), counting each mesh's triangles
  (index or position count / 3) once per node that instances it, as the scene is flattened;
- ``.stl``: the triangle count of a binary file's header, else the ``facet`` lines of an ASCII one;
- ``.obj`` / ``.off``: their face lines, streamed (an ``.obj`` polygon of n corners is n - 2 triangles).

:func:`check_scene_mesh` then checks what was loaded before anything uses it: the triangle bound again (any
format), finite vertices, and face indices within the vertices.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.io.bounded_read import parse_json, read_json
from skeleton_mamba.tasks.egodance.builder.config import MAX_SCENE_FACES  # plain Python, for --help

__all__ = ["MAX_SCENE_FACES", "SceneFileError", "check_face_count", "check_scene_file", "check_scene_mesh"]

_MAX_HEADER_BYTES = 1 << 16  # a PLY header
_MAX_GLTF_JSON_BYTES = 64 << 20  # the JSON of a glTF scene
_BLOCK = 1 << 20


class SceneFileError(DataFileError):
    """A scene file that cannot be used (the message names the file and what is wrong)."""


def check_face_count(path: Path, faces: int, max_faces: int) -> None:
    """Refuse ``faces`` triangles when more than ``max_faces`` (naming ``path``)."""
    if faces > max_faces:
        raise SceneFileError(
            f"{path}: {faces:,} triangles, more than the {max_faces:,} a scene may have (decimate it, or "
            "raise the bound with --max-faces)"
        )


def check_scene_file(path: str | Path, max_faces: int = MAX_SCENE_FACES) -> None:
    """Refuse a scene file declaring more than ``max_faces`` triangles (module docstring), before loading.

    Raises:
        SceneFileError: naming the file, what it declares and the bound; or a malformed header.
        OSError: unreadable.
    """
    path = Path(path)
    counter = {".ply": _ply_faces, ".glb": _glb_faces, ".gltf": _gltf_faces, ".stl": _stl_faces}.get(
        path.suffix.lower(), _face_lines
    )
    check_face_count(path, counter(path, max_faces), max_faces)


def _ply_faces(path: Path, max_faces: int) -> int:
    with open(path, "rb") as f:
        head = f.read(_MAX_HEADER_BYTES)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise SceneFileError(f"{path}: not a PLY file (no 'ply' ... 'end_header' header in its first 64 KiB)")
    counts = {}
    for line in head[:end].decode("ascii", "replace").splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == "element":
            if not parts[2].isdigit():
                raise SceneFileError(f"{path}: bad PLY header line {line.strip()!r}")
            counts[parts[1]] = int(parts[2])
    check_face_count(
        path, counts.get("vertex", 0) // 3, max_faces
    )  # more vertices than any bounded mesh needs
    return counts.get("face", 0)


def _gltf_triangles(document: object, path: Path) -> int:
    """Triangles of a glTF document once every node's mesh is flattened."""
    if not isinstance(document, dict):
        raise SceneFileError(f"{path}: not a glTF document (its JSON is not an object)")
    accessors, meshes, nodes = (document.get(k) or [] for k in ("accessors", "meshes", "nodes"))
    if not all(isinstance(x, list) for x in (accessors, meshes, nodes)):
        raise SceneFileError(f"{path}: accessors, meshes and nodes must be lists")

    def count(index: object) -> int:
        entry = accessors[index] if isinstance(index, int) and 0 <= index < len(accessors) else None
        value = entry.get("count") if isinstance(entry, dict) else None
        if not isinstance(value, int) or value < 0:
            raise SceneFileError(f"{path}: accessor {index!r} is missing or has no count")
        return value

    per_mesh = []
    for mesh in meshes:
        total = 0
        for primitive in (mesh.get("primitives") or []) if isinstance(mesh, dict) else []:
            if not isinstance(primitive, dict):
                continue
            if "indices" in primitive:
                total += count(primitive["indices"]) // 3
            elif isinstance(primitive.get("attributes"), dict) and "POSITION" in primitive["attributes"]:
                total += count(primitive["attributes"]["POSITION"]) // 3
        per_mesh.append(total)
    instanced = [n.get("mesh") for n in nodes if isinstance(n, dict) and isinstance(n.get("mesh"), int)]
    return sum(per_mesh[m] for m in instanced if 0 <= m < len(per_mesh)) or sum(per_mesh)


def _glb_faces(path: Path, max_faces: int) -> int:
    with open(path, "rb") as f:
        header = f.read(20)
        if len(header) < 20 or header[:4] != b"glTF":
            raise SceneFileError(f"{path}: not a binary glTF file (no 'glTF' header)")
        length, kind = struct.unpack("<II", header[12:20])
        if kind != 0x4E4F534A or length > _MAX_GLTF_JSON_BYTES:
            raise SceneFileError(
                f"{path}: its first chunk is not JSON of at most {_MAX_GLTF_JSON_BYTES:,} bytes"
            )
        text = f.read(length)
    return _gltf_triangles(parse_json(text, f"{path} (glTF JSON)", error=SceneFileError), path)


def _gltf_faces(path: Path, max_faces: int) -> int:
    document = read_json(path, max_bytes=_MAX_GLTF_JSON_BYTES, what="glTF file", error=SceneFileError)
    return _gltf_triangles(document, path)


def _stl_faces(path: Path, max_faces: int) -> int:
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(84)
    if len(head) == 84 and 84 + 50 * struct.unpack("<I", head[80:84])[0] == size:
        return struct.unpack("<I", head[80:84])[0]  # binary STL: its count matches its size
    return _count_lines(path, (b"facet",), max_faces, polygons=False)


def _face_lines(path: Path, max_faces: int) -> int:
    if path.suffix.lower() == ".off":
        with open(path, "rb") as f:
            lines = f.read(_MAX_HEADER_BYTES).split(b"\n")
        counts = lines[1].split() if lines and lines[0].strip().endswith(b"OFF") and len(lines) > 1 else []
        return int(counts[1]) if len(counts) >= 2 and counts[1].isdigit() else 0
    return _count_lines(path, (b"f ", b"f\t"), max_faces, polygons=True)


def _count_lines(path: Path, prefixes: tuple[bytes, ...], max_faces: int, polygons: bool) -> int:
    """Triangles of the lines starting with ``prefixes`` (one each; ``polygons``: a line of n corners gives
    n - 2), streamed, stopping once past ``max_faces``."""
    faces, rest = 0, b""
    with open(path, "rb") as f:
        while faces <= max_faces:
            block = f.read(_BLOCK)
            if not block:
                break
            lines = (rest + block).split(b"\n")
            rest = lines.pop()
            for line in lines:
                stripped = line.lstrip()
                if stripped.startswith(prefixes):
                    faces += max(1, len(stripped.split()) - 3) if polygons else 1
    return faces


def check_scene_mesh(path: Path | str, vertices: np.ndarray, faces: np.ndarray, max_faces: int) -> None:
    """Refuse a loaded scene with more than ``max_faces`` triangles, a non-finite vertex, or a face index
    outside its vertices (naming the file)."""
    path = Path(path)
    check_face_count(path, len(faces), max_faces)
    vertices = np.asarray(vertices)
    bad = ~np.isfinite(vertices).all(axis=-1)
    if bad.any():
        first = int(np.argmax(bad))
        raise SceneFileError(
            f"{path}: vertex {first} is {vertices[first].tolist()} ({int(bad.sum())} vertices not finite)"
        )
    faces = np.asarray(faces)
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise SceneFileError(
            f"{path}: a face refers to vertex {int(faces.max())}, the scene has {len(vertices)}"
        )
