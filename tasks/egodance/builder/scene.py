"""Scene meshes for the EgoAIST++ builder: loading, up-axis conversion, colours and the floor.

Any file trimesh loads works (``.glb``/``.gltf``, ``.obj``, ``.ply``, Replica's ``mesh.ply``). A multi-part
scene is flattened into ONE triangle mesh with per-vertex RGBA colours: vertex colours are kept, textured
parts are sampled at their vertices (``trimesh`` ``TextureVisuals.to_color``), untextured materials give
their base colour. The mesh is converted to the toolkit's y-up frame at load time (DESIGN.md): a z-up scene
(Replica, Habitat test scenes) is rotated by -90 degrees about x, ``(x, y, z) -> (x, z, -y)``.

The floor is the LOWEST height whose area of upward-facing triangles (normal . up > 0.9) is at least half
of the largest such area, on a 2 cm histogram of triangle heights (the lowest so that the top of a
ceiling slab, often as large as the floor, is never taken); the floor triangles are those upward-facing
ones within ``floor_tolerance`` of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from skeleton_mamba.tasks.egodance.builder.ray_caster import RayCaster
from skeleton_mamba.tasks.egodance.builder.scene_check import (
    MAX_SCENE_FACES,
    SceneFileError,
    check_face_count,
    check_scene_file,
    check_scene_mesh,
)

__all__ = ["SceneMesh", "load_scene", "to_y_up", "UP_AXES"]

# Rotation taking a scene with the given up axis to y-up (right-handed, det = +1).
UP_AXES: dict[str, np.ndarray] = {
    "y": np.eye(3),
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
    "x": np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
}
DEFAULT_GREY = np.array([180, 180, 180, 255], dtype=np.uint8)


def to_y_up(up_axis: str) -> np.ndarray:
    """The (3, 3) rotation from a scene whose up axis is ``up_axis`` ("x", "y" or "z") to y-up."""
    if up_axis not in UP_AXES:
        raise ValueError(f"up axis must be one of {sorted(UP_AXES)}, got {up_axis!r}")
    return UP_AXES[up_axis]


@dataclass
class SceneMesh:
    """A y-up scene: one triangle mesh with vertex colours, plus its floor.

    Attributes:
        name: identifier written into the sample metadata (file stem or ``procedural-<seed>``).
        mesh: the y-up triangle mesh; ``mesh.visual.vertex_colors`` is (V, 4) uint8.
        floor_height: y of the floor (metres).
        floor_faces: indices of the floor triangles (placement samples locations on them).
        source: where the scene came from (a path or a procedural description).
    """

    name: str
    mesh: trimesh.Trimesh
    floor_height: float
    floor_faces: np.ndarray
    source: str = ""
    _caster: RayCaster | None = field(default=None, repr=False, compare=False)

    @property
    def vertex_colors(self) -> np.ndarray:
        """(V, 3) float RGB in [0, 1]."""
        return np.asarray(self.mesh.visual.vertex_colors[:, :3], dtype=np.float64) / 255.0

    @property
    def caster(self) -> RayCaster:
        """The scene's cached :class:`~.ray_caster.RayCaster` (embree when ``embreex`` is installed)."""
        if self._caster is None:
            self._caster = RayCaster(self.mesh.vertices, self.mesh.faces)
        return self._caster

    def sample_floor(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """``count`` points uniformly distributed (by area) over the floor triangles, shape (count, 3)."""
        tris = self.mesh.triangles[self.floor_faces]
        area = self.mesh.area_faces[self.floor_faces]
        idx = rng.choice(len(tris), size=count, p=area / area.sum())
        u, v = rng.random(count), rng.random(count)
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        t = tris[idx]
        return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])

    def __getstate__(self) -> dict:  # the embree handle is not picklable: workers rebuild it
        state = self.__dict__.copy()
        state["_caster"] = None
        return state


def _part_colors(geom: trimesh.Trimesh) -> np.ndarray:
    """(V, 4) uint8 vertex colours of one part, from its vertex colours, texture or material."""
    visual = geom.visual
    if visual.kind == "vertex":
        return np.asarray(visual.vertex_colors, dtype=np.uint8)
    if visual.kind == "face":
        colors = np.zeros((len(geom.vertices), 4), dtype=np.float64)
        counts = np.zeros(len(geom.vertices))
        for k in range(3):
            np.add.at(colors, geom.faces[:, k], visual.face_colors)
            np.add.at(counts, geom.faces[:, k], 1)
        return (colors / np.maximum(counts, 1)[:, None]).astype(np.uint8)
    if visual.kind == "texture":
        # a material without an image gives one colour; broadcast it to every vertex
        colors = np.asarray(visual.to_color().vertex_colors, dtype=np.uint8)
        return np.broadcast_to(colors, (len(geom.vertices), colors.shape[-1])).copy()
    material = getattr(visual, "material", None)
    base = getattr(material, "baseColorFactor", None) if material is not None else None
    color = DEFAULT_GREY if base is None else np.asarray(base, dtype=np.uint8)
    return np.tile(color, (len(geom.vertices), 1))


def _flatten(loaded, path: Path, max_faces: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (world frame), faces and vertex colours of everything ``trimesh.load`` returned (refused
    before they are copied when the instanced parts hold more than ``max_faces`` triangles)."""
    if isinstance(loaded, trimesh.Trimesh):
        parts = [(loaded, np.eye(4))]
    elif isinstance(loaded, trimesh.Scene):
        parts = []
        for node in loaded.graph.nodes_geometry:
            transform, name = loaded.graph[node]
            geom = loaded.geometry[name]
            if isinstance(geom, trimesh.Trimesh):
                parts.append((geom, transform))
    else:
        raise SceneFileError(
            f"{path}: not a triangle mesh or scene (trimesh returned {type(loaded).__name__})"
        )
    if not parts or all(len(g.faces) == 0 for g, _ in parts):
        raise SceneFileError(f"{path}: the scene contains no triangles")
    check_face_count(path, sum(len(g.faces) for g, _ in parts), max_faces)  # instances counted, not copied
    verts, faces, colors, offset = [], [], [], 0
    for geom, transform in parts:
        v = trimesh.transformations.transform_points(np.asarray(geom.vertices), transform)
        verts.append(v)
        faces.append(np.asarray(geom.faces) + offset)
        colors.append(_part_colors(geom))
        offset += len(v)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(colors)


def find_floor(
    mesh: trimesh.Trimesh, floor_tolerance: float = 0.03, bin_size: float = 0.02
) -> tuple[float, np.ndarray]:
    """The floor height and floor triangle indices of a y-up mesh (see the module docstring).

    Raises:
        ValueError: when the mesh has no upward-facing triangles.
    """
    up = mesh.face_normals[:, 1] > 0.9
    if not up.any():
        raise ValueError("the scene has no upward-facing triangles: no floor (is the up axis right?)")
    heights = mesh.triangles_center[up, 1]
    areas = mesh.area_faces[up]
    lo = heights.min()
    bins = np.floor((heights - lo) / bin_size).astype(np.int64)
    area_per_bin = np.bincount(bins, weights=areas)
    best = int(np.flatnonzero(area_per_bin >= 0.5 * area_per_bin.max())[0])
    in_bin = bins == best
    floor = float(np.average(heights[in_bin], weights=areas[in_bin]))
    faces = np.flatnonzero(up)[np.abs(heights - floor) <= floor_tolerance]
    return floor, faces


def make_scene(
    name: str, vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray, source: str = ""
) -> SceneMesh:
    """A :class:`SceneMesh` from y-up arrays: vertices (V, 3), faces (F, 3), colours (V, 3|4) uint8."""
    colors = np.asarray(colors, dtype=np.uint8)
    if colors.shape[1] == 3:
        colors = np.concatenate([colors, np.full((len(colors), 1), 255, np.uint8)], axis=1)
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, vertex_colors=colors, process=False)
    # drop zero-area triangles (their normals are undefined) without merging vertices (keeps colours)
    mesh.update_faces(mesh.area_faces > 1e-12)
    floor, floor_faces = find_floor(mesh)
    return SceneMesh(name=name, mesh=mesh, floor_height=floor, floor_faces=floor_faces, source=source)


def load_scene(path: str | Path, up_axis: str = "y", max_faces: int = MAX_SCENE_FACES) -> SceneMesh:
    """Load a scene mesh file and convert it to y-up.

    Args:
        path: any mesh or scene file trimesh can load (``.glb``, ``.obj``, ``.ply``, ...).
        up_axis: the file's up axis, ``"y"`` (glTF default), ``"z"`` (Replica, Habitat) or ``"x"``.
        max_faces: the most triangles it may hold, checked from its header before it is loaded
            (:mod:`.scene_check`) and on what was loaded.

    Raises:
        FileNotFoundError: the file does not exist.
        SceneFileError: the file is not a triangle mesh, is empty, too large, holds a non-finite vertex or
            has no floor.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"scene file not found: {path}")
    rotation = to_y_up(up_axis)
    check_scene_file(path, max_faces)
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as err:  # trimesh raises many types for broken files
        raise SceneFileError(f"{path}: trimesh cannot load this scene ({err})") from err
    vertices, faces, colors = _flatten(loaded, path, max_faces)
    check_scene_mesh(path, vertices, faces, max_faces)
    try:
        return make_scene(path.stem, vertices @ rotation.T, faces, colors, source=str(path))
    except ValueError as err:
        raise SceneFileError(f"{path}: {err}") from err
