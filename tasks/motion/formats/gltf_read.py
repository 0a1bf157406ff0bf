"""Read a motion ``.glb`` back: the skinned skeleton and animation that :mod:`.gltf` writes.

``sm view``, ``sm render`` and ``sm export`` take their own glTF exports (and files of the same layout from
other tools): the joints are the first skin's joints (names from the nodes, parents from the node tree),
their rest offsets the nodes' translations, the motion the first animation's ``translation`` / ``rotation``
channels, one key per frame (``LINEAR`` or ``STEP``; every channel on the same key times, evenly spaced,
which give the frame rate). glTF lengths are metres.

Everything is checked before use, naming the file: the file size (:data:`MAX_GLB_BYTES`), that every index
points inside its table, the layout of every accessor and buffer view by glTF 2.0's rules as the Khronos
validator applies them (:func:`check_layout`), float32 values, finite numbers, a joint tree without cycles,
and a frame rate in the toolkit's range. Anything else (a cubic-spline or morph-target animation, a node
matrix or scale, a skin-less file) is refused on one line.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np
import pygltflib
import torch

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.skeletons import parents_first_order
from skeleton_mamba.tasks.motion.body.rotations import quaternion_to_matrix
from skeleton_mamba.tasks.motion.formats.gltf import SkeletonMotion
from skeleton_mamba.tasks.motion.formats.registry import MOTION_FORMATS, FileMotion, ReadRequest
from skeleton_mamba.tasks.motion.formats.units import METRES
from skeleton_mamba.tasks.motion.io.value_checks import check_fps, non_finite_message

__all__ = ["GltfError", "MAX_GLB_BYTES", "check_layout", "read_glb"]

MAX_GLB_BYTES = 1 << 30
_WIDTH = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}
# glTF 2.0's accessor types (components per element) and component types (bytes per component)
_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_DTYPES = {5120: np.dtype("<i1"), 5121: np.dtype("<u1"), 5122: np.dtype("<i2"), 5123: np.dtype("<u2"),
           5125: np.dtype("<u4"), 5126: np.dtype("<f4")}  # fmt: skip
_MAX_STRIDE = 252  # bufferView.byteStride: 4 to 252, a multiple of 4
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
        """(count, width) float64 values of float32 accessor ``index`` of type ``kind`` (its layout checked
        by :func:`check_layout` before anything is read)."""
        acc = self.gltf.accessors[self.index(index, self.gltf.accessors, "accessor")]
        if acc.type != kind or acc.componentType != pygltflib.FLOAT or acc.sparse is not None:
            found = f"{acc.componentType} {acc.type}"
            raise self.fail(f"accessor {index}: expected dense float {kind}, got {found}")
        view = self.gltf.bufferViews[acc.bufferView]
        width = _WIDTH[kind]
        if view.byteStride not in (None, 4 * width):
            raise self.fail(f"accessor {index}: interleaved buffer views (byteStride) are not read")
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        values = np.frombuffer(self.blob, "<f4", acc.count * width, start).reshape(acc.count, width)
        message = non_finite_message(values, f"accessor {index}")
        if message is not None:
            raise self.fail(message)
        return values.astype(np.float64)

    def values(self, index, kinds: tuple[str, ...]) -> np.ndarray:
        """(count, width) values of accessor ``index`` of any component type (a ``normalized`` integer
        accessor mapped to [0, 1] or [-1, 1] as glTF says), interleaved views followed by their stride;
        float64 for floats and normalized values, int64 for integers."""
        acc = self.gltf.accessors[self.index(index, self.gltf.accessors, "accessor")]
        if acc.type not in kinds or acc.sparse is not None:
            raise self.fail(f"accessor {index}: expected dense {' or '.join(kinds)}, got {acc.type}")
        view = self.gltf.bufferViews[acc.bufferView]
        width, dtype = _COMPONENTS[acc.type], _DTYPES[acc.componentType]
        element = width * dtype.itemsize
        stride = view.byteStride or element
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        raw = np.frombuffer(self.blob, np.uint8, stride * (acc.count - 1) + element, start)
        rows = np.lib.stride_tricks.as_strided(raw, (acc.count, element), (stride, 1))
        values = np.ascontiguousarray(rows).view(dtype).reshape(acc.count, width)
        if acc.componentType == pygltflib.FLOAT:
            message = non_finite_message(values, f"accessor {index}")
            if message is not None:
                raise self.fail(message)
            return values.astype(np.float64)
        if acc.normalized:
            return np.maximum(values / float(np.iinfo(dtype).max), -1.0)
        return values.astype(np.int64)


def _natural(value, low: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


def _element_bytes(kind: str, component: int) -> int:
    """Bytes of one element; a matrix's columns start on 4-byte boundaries (MAT2 / MAT3 of 1- or 2-byte
    components are padded)."""
    size = _COMPONENT_BYTES[component]
    if kind in ("MAT2", "MAT3"):
        rows = 2 if kind == "MAT2" else 3
        return rows * -(-rows * size // 4) * 4
    return _COMPONENTS[kind] * size


def check_layout(r: _Reader) -> None:
    """glTF 2.0's layout rules, as the Khronos glTF validator applies them, for every buffer, buffer view and
    accessor of the file, before any value is read (a refusal names the file and the accessor, or the
    buffer view no accessor uses):

    - a buffer: ``byteLength >= 1``; the GLB's own buffer (no ``uri``) within its BIN chunk, which is at most
      3 bytes of padding longer; a buffer with a ``uri`` (an external file) is not read;
    - a buffer view: ``byteOffset >= 0``, ``byteLength >= 1``, inside its buffer; ``byteStride``, when
      given, 4 to 252 and a multiple of 4;
    - an accessor: a known ``type`` and ``componentType``; ``count >= 1``; ``byteOffset >= 0`` and a
      multiple of the component size, as is its total offset in the buffer; a view's ``byteStride`` at
      least one element; its elements inside its buffer view (``byteOffset + stride * (count - 1) +
      element size <= byteLength``).
    """
    gltf = r.gltf
    for b, buffer in enumerate(gltf.buffers):
        if not _natural(buffer.byteLength, 1):
            raise r.fail(f"buffer {b}: byteLength {buffer.byteLength!r} must be an integer >= 1")
        if buffer.uri is not None:
            raise r.fail(f"buffer {b}: an external buffer ({buffer.uri!r}) is not read (the GLB's own only)")
        if b == 0 and not buffer.byteLength <= len(r.blob) <= buffer.byteLength + 3:
            raise r.fail(f"buffer 0: byteLength {buffer.byteLength:,} does not match the binary chunk's "
                         f"{len(r.blob):,} bytes (at most 3 bytes of padding)")  # fmt: skip
    if len(gltf.buffers) > 1:
        raise r.fail(
            f"{len(gltf.buffers)} buffers: a GLB holds one without a uri (buffer 0), and no other is read"
        )
    used: set[int] = set()
    for a, acc in enumerate(gltf.accessors):
        if acc.bufferView is None:
            raise r.fail(f"accessor {a}: no bufferView (its values would all be zeros): not read")
        view = r.index(acc.bufferView, gltf.bufferViews, f"accessor {a}: bufferView")
        used.add(view)
        _check_view(r, view, f"accessor {a}: bufferView {view}")
        _check_accessor(r, a, acc, gltf.bufferViews[view])
    for v in range(len(gltf.bufferViews)):
        if v not in used:
            _check_view(r, v, f"bufferView {v}")


def _check_view(r: _Reader, index: int, where: str) -> None:
    view = r.gltf.bufferViews[index]
    buffer = r.index(view.buffer, r.gltf.buffers, f"{where}: buffer")
    offset = 0 if view.byteOffset is None else view.byteOffset
    if not _natural(offset, 0):
        raise r.fail(f"{where}: byteOffset {offset!r} must be an integer >= 0")
    if not _natural(view.byteLength, 1):
        raise r.fail(f"{where}: byteLength {view.byteLength!r} must be an integer >= 1")
    size = r.gltf.buffers[buffer].byteLength
    if offset + view.byteLength > size:
        raise r.fail(f"{where}: bytes {offset:,} to {offset + view.byteLength:,} lie outside buffer {buffer} "
                     f"({size:,} bytes)")  # fmt: skip
    stride = view.byteStride
    if stride is not None and (not _natural(stride, 4) or stride > _MAX_STRIDE or stride % 4):
        raise r.fail(f"{where}: byteStride {stride!r} must be a multiple of 4 from 4 to {_MAX_STRIDE}")


def _check_accessor(r: _Reader, index: int, acc, view) -> None:
    where = f"accessor {index}"
    if acc.type not in _COMPONENTS or acc.componentType not in _COMPONENT_BYTES:
        raise r.fail(f"{where}: type {acc.type!r} of componentType {acc.componentType!r} is not glTF 2.0's")
    if not _natural(acc.count, 1):
        raise r.fail(f"{where}: count {acc.count!r} must be an integer >= 1")
    offset = 0 if acc.byteOffset is None else acc.byteOffset
    if not _natural(offset, 0):
        raise r.fail(f"{where}: byteOffset {offset!r} must be an integer >= 0")
    component = _COMPONENT_BYTES[acc.componentType]
    if offset % component:
        raise r.fail(
            f"{where}: byteOffset {offset} is not a multiple of its component size ({component} bytes)"
        )
    total = (view.byteOffset or 0) + offset
    if total % component:
        raise r.fail(f"{where}: its offset in the buffer ({total}: bufferView {acc.bufferView}'s byteOffset "
                     f"+ its own) is not a multiple of its component size ({component} bytes)")  # fmt: skip
    element = _element_bytes(acc.type, acc.componentType)
    stride = element if view.byteStride is None else view.byteStride
    if stride < element:
        raise r.fail(f"{where}: bufferView {acc.bufferView}'s byteStride {stride} is less than one element "
                     f"({element} bytes)")  # fmt: skip
    needed = offset + stride * (acc.count - 1) + element
    if needed > view.byteLength:
        raise r.fail(f"{where}: {acc.count} values do not fit in bufferView {acc.bufferView} (they need "
                     f"bytes {offset:,} to {needed:,} of its {view.byteLength:,})")  # fmt: skip


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
        >>> from skeleton_mamba.tasks.motion.formats.gltf import from_joints, write_glb
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
    check_layout(r)  # every accessor and buffer view, before any value is read
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


@MOTION_FORMATS.register(".glb")
def read_glb_motion(path: Path, request: ReadRequest) -> FileMotion:
    """a motion glTF as ``sm export`` writes it"""
    return FileMotion(read_glb(path))
