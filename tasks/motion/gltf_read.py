"""Read a motion ``.glb`` back: the skinned skeleton and animation that :mod:`.gltf` writes.

``sm view``, ``sm render`` and ``sm export`` take their own glTF exports (and files of the same layout from
other tools): the joints are the first skin's joints (names from the nodes, parents from the node tree),
their rest offsets the nodes' translations, the motion the first animation's ``translation`` / ``rotation``
channels, one key per frame (``LINEAR`` or ``STEP``; every channel on the same key times, evenly spaced,
which give the frame rate). glTF lengths are metres.

Everything is checked before use, naming the file: the file size (:data:`MAX_GLB_BYTES`), that every index
points inside its table, that accessors lie inside their buffer views and the binary chunk, float32 values,
finite numbers, a joint tree without cycles, and a frame rate in the toolkit's range. Anything else (a
cubic-spline or morph-target animation, a node matrix or scale, a skin-less file) is refused on one line.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np
import pygltflib
import torch

from skeleton_mamba.skeletons import parents_first_order
from skeleton_mamba.tasks.motion.errors import DataFileError
from skeleton_mamba.tasks.motion.gltf import SkeletonMotion
from skeleton_mamba.tasks.motion.rotations import quaternion_to_matrix
from skeleton_mamba.tasks.motion.units import METRES
from skeleton_mamba.tasks.motion.value_checks import check_fps, non_finite_message

__all__ = ["GltfError", "MAX_GLB_BYTES", "read_glb"]

MAX_GLB_BYTES = 1 << 30
_WIDTH = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_DEFAULT_FPS = 30.0  # a single-key animation carries no spacing: ``asset.extras.fps`` or this


class GltfError(DataFileError):
    """A ``.glb`` is malformed or not a skeleton motion (the message names the file)."""


class _Reader:
    def __init__(self, path: Path, gltf: pygltflib.GLTF2, blob: bytes) -> None:
        self.path, self.gltf, self.blob = path, gltf, blob

    def fail(self, message: str) -> GltfError:
        return GltfError(f"{self.path}: {message}")

    def index(self, value, table: list, what: str) -> int:
        if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < len(table):
            raise self.fail(f"{what} index {value!r} is outside 0-{len(table) - 1}")
        return value

    def accessor(self, index, kind: str) -> np.ndarray:
        """(count, width) float64 values of float32 accessor ``index`` of type ``kind``."""
        acc = self.gltf.accessors[self.index(index, self.gltf.accessors, "accessor")]
        if acc.type != kind or acc.componentType != pygltflib.FLOAT or acc.sparse is not None:
            found = f"{acc.componentType} {acc.type}"
            raise self.fail(f"accessor {index}: expected dense float {kind}, got {found}")
        view = self.gltf.bufferViews[self.index(acc.bufferView, self.gltf.bufferViews, "bufferView")]
        width = _WIDTH[kind]
        if view.byteStride not in (None, 4 * width) or view.buffer != 0:
            raise self.fail(f"accessor {index}: interleaved or external buffer views are not read")
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        size = 4 * width * int(acc.count)
        if acc.count < 1 or (acc.byteOffset or 0) + size > view.byteLength or start + size > len(self.blob):
            raise self.fail(f"accessor {index}: {acc.count} values do not fit in the binary chunk")
        values = np.frombuffer(self.blob, "<f4", acc.count * width, start).reshape(acc.count, width)
        message = non_finite_message(values, f"accessor {index}")
        if message is not None:
            raise self.fail(message)
        return values.astype(np.float64)


def _load(path: Path) -> tuple[pygltflib.GLTF2, bytes]:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such glTF file")
    size = path.stat().st_size
    if size > MAX_GLB_BYTES:
        limit = f"{MAX_GLB_BYTES >> 20} MiB"
        raise GltfError(f"{path}: {size / 2**20:.0f} MiB, above the {limit} a motion file may take")
    if path.read_bytes()[:4] != b"glTF":
        raise GltfError(f"{path}: not a binary glTF (.glb) file (no 'glTF' magic)")
    try:
        gltf = pygltflib.GLTF2().load_binary(str(path))
    except Exception as err:  # pygltflib raises whatever its JSON / dataclass parsing meets
        raise GltfError(f"{path}: unreadable glTF ({type(err).__name__}: {err})") from None
    if gltf is None:
        raise GltfError(f"{path}: unreadable glTF")
    return gltf, bytes(gltf.binary_blob() or b"")


def read_glb(path: str | PathLike[str]) -> SkeletonMotion:
    """The :class:`SkeletonMotion` of a ``.glb`` (module docstring); raises :class:`GltfError`.

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> from skeleton_mamba.tasks.motion.gltf import from_joints, write_glb
        >>> joints = np.zeros((3, 24, 3))
        >>> joints[:, :, 1] = np.linspace(0.0, 1.7, 24)
        >>> path = write_glb(from_joints(joints, "smpl24", 30.0), Path(tempfile.mkdtemp()) / "clip.glb")
        >>> motion = read_glb(path)
        >>> len(motion.names), motion.fps, motion.translations.shape
        (24, 30.0, (3, 24, 3))
    """
    path = Path(path)
    gltf, blob = _load(path)
    r = _Reader(path, gltf, blob)
    if not gltf.skins:
        raise r.fail("holds no skin: not a skeleton motion (sm export writes one skinned skeleton)")
    joints = [r.index(n, gltf.nodes, "skin joint node") for n in gltf.skins[0].joints or []]
    if not joints or len(set(joints)) != len(joints):
        raise r.fail("the skin lists no joints, or one twice")
    slot = {node: j for j, node in enumerate(joints)}
    parents = [-1] * len(joints)
    for n, node in enumerate(gltf.nodes):
        for c in node.children or []:
            r.index(c, gltf.nodes, f"node {n} child")
            if c in slot and n in slot:
                if parents[slot[c]] != -1:
                    raise r.fail(f"node {c} has two parents")
                parents[slot[c]] = slot[n]
    try:
        parents_first_order(parents, str(path))
    except ValueError as err:
        raise r.fail("the joints' node tree has a cycle") from err
    offsets = np.zeros((len(joints), 3))
    rest_rotation = np.tile([1.0, 0.0, 0.0, 0.0], (len(joints), 1))  # w x y z
    for j, n in enumerate(joints):
        node = gltf.nodes[n]
        if node.matrix is not None or (node.scale is not None and list(node.scale) != [1, 1, 1]):
            raise r.fail(f"node {n} ({node.name}) has a matrix or a scale: not a skeleton-motion joint")
        offsets[j] = _vector(r, node.translation, 3, f"node {n} translation", [0.0, 0.0, 0.0])
        x, y, z, w = _vector(r, node.rotation, 4, f"node {n} rotation", [0.0, 0.0, 0.0, 1.0])
        rest_rotation[j] = [w, x, y, z]

    times, tracks = _animation(r, slot)
    frames = len(times)
    fps = _frame_rate(r, times)
    translations = np.repeat(offsets[None], frames, axis=0)
    quaternions = np.repeat(rest_rotation[None], frames, axis=0)
    translated = [False] * len(joints)
    rotated = False
    for (j, kind), values in tracks.items():
        if kind == "translation":
            translations[:, j], translated[j] = values, True
        else:
            quaternions[:, j] = values[:, [3, 0, 1, 2]]
            rotated = True
    rotations = None
    if rotated or np.any(rest_rotation != [1.0, 0.0, 0.0, 0.0]):
        if np.any(np.linalg.norm(quaternions, axis=-1) < 1e-6):
            raise r.fail("a rotation key is a zero quaternion")
        rotations = quaternion_to_matrix(torch.from_numpy(quaternions)).numpy()
    names = [gltf.nodes[n].name or f"joint{j}" for j, n in enumerate(joints)]
    return SkeletonMotion(names, parents, fps, offsets, translations, rotations, translated, METRES)


def _vector(r: _Reader, value, size: int, what: str, default: list[float]) -> np.ndarray:
    if value is None:
        return np.asarray(default)
    array = np.asarray(value, dtype=np.float64) if isinstance(value, list) else None
    if array is None or array.shape != (size,) or not np.isfinite(array).all():
        raise r.fail(f"{what} must be {size} finite numbers, got {value!r}")
    return array


def _animation(r: _Reader, slot: dict[int, int]) -> tuple[np.ndarray, dict[tuple[int, str], np.ndarray]]:
    """Key times (T,) and {(joint, 'translation' | 'rotation'): (T, 3 | 4) values}; one rest frame when the
    file has no animation."""
    if not r.gltf.animations:
        return np.zeros(1), {}
    animation = r.gltf.animations[0]
    times: np.ndarray | None = None
    tracks: dict[tuple[int, str], np.ndarray] = {}
    for ch in animation.channels or []:
        sampler = animation.samplers[r.index(ch.sampler, animation.samplers, "animation sampler")]
        node = ch.target.node if ch.target is not None else None
        path = ch.target.path if ch.target is not None else None
        if node not in slot or path not in ("translation", "rotation"):
            raise r.fail(f"animation channel on node {node} path {path!r}: only joints' translation and "
                         "rotation are read")  # fmt: skip
        if sampler.interpolation not in (None, "LINEAR", "STEP"):
            raise r.fail(f"{sampler.interpolation} animation is not read (one key per frame: LINEAR or STEP)")
        keys = r.accessor(sampler.input, "SCALAR")[:, 0]
        if times is None:
            times = keys
        elif len(keys) != len(times) or np.abs(keys - times).max() > 1e-4:
            raise r.fail("animation channels have different key times (one key per frame expected)")
        values = r.accessor(sampler.output, "VEC3" if path == "translation" else "VEC4")
        if len(values) != len(times):
            raise r.fail(f"channel of node {node}: {len(values)} values for {len(times)} key times")
        tracks[(slot[node], path)] = values
    return (np.zeros(1) if times is None else times), tracks


def _frame_rate(r: _Reader, times: np.ndarray) -> float:
    if len(times) < 2:
        extras = r.gltf.asset.extras if r.gltf.asset is not None else None
        fps = extras.get("fps", _DEFAULT_FPS) if isinstance(extras, dict) else _DEFAULT_FPS
        fps = float(fps) if isinstance(fps, (int, float)) and not isinstance(fps, bool) else _DEFAULT_FPS
    else:
        step = float(times[-1] - times[0]) / (len(times) - 1)
        rounding = 4 * float(np.finfo(np.float32).eps) * float(np.abs(times).max())  # float32 key times
        if step <= 0 or np.abs(np.diff(times) - step).max() > 1e-3 * step + rounding:
            raise r.fail("animation keys are not evenly spaced frames (one key per frame expected)")
        fps = 1.0 / step
        fps = float(round(fps)) if abs(fps - round(fps)) < 1e-3 * fps else fps
    try:
        return check_fps(fps, f"{r.path}: frame rate")
    except ValueError as err:
        raise GltfError(str(err)) from None
