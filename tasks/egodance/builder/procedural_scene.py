"""Procedural furnished rooms (``--scenes procedural``), y-up, deterministic from a seed.

A room is a tiled floor (a checkerboard of two colours, the "texture"), four walls made of a skirting band,
a main band and a top band in different colours, a ceiling slab, and furniture: boxes (cabinets, crates)
and tables (a top on four legs). Every part is a closed box (``trimesh.creation.box``) with outward
normals, so the penetration score's inside test is well defined; furniture footprints do not overlap each
other. Sizes are drawn uniformly from the ranges in :class:`RoomSpec`.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass

import numpy as np
import trimesh

from skeleton_mamba.tasks.egodance.builder.scene import SceneMesh, make_scene

__all__ = ["RoomSpec", "procedural_room"]


@dataclass(frozen=True)
class RoomSpec:
    """Ranges for a procedural room (metres)."""

    width: tuple[float, float] = (5.0, 9.0)
    depth: tuple[float, float] = (5.0, 9.0)
    height: tuple[float, float] = (2.5, 3.2)
    tile: tuple[float, float] = (0.4, 0.8)
    num_boxes: tuple[int, int] = (2, 5)
    num_tables: tuple[int, int] = (1, 3)
    wall_thickness: float = 0.1


def _color(rng: np.random.Generator, sat: tuple[float, float] = (0.2, 0.8), val=(0.35, 0.95)) -> np.ndarray:
    rgb = colorsys.hsv_to_rgb(rng.random(), rng.uniform(*sat), rng.uniform(*val))
    return (np.array(rgb) * 255).astype(np.uint8)


# trimesh's unit box (outward normals), built once: creating a Trimesh per box dominated room creation
_UNIT_BOX = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
_UNIT_BOX_VERTICES = np.asarray(_UNIT_BOX.vertices, dtype=np.float64)
_UNIT_BOX_FACES = np.asarray(_UNIT_BOX.faces, dtype=np.int64)


class _Builder:
    """Accumulates coloured boxes."""

    def __init__(self) -> None:
        self.vertices: list[np.ndarray] = []
        self.faces: list[np.ndarray] = []
        self.colors: list[np.ndarray] = []
        self.count = 0

    def box(self, lo: np.ndarray, hi: np.ndarray, color: np.ndarray) -> None:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        vertices = _UNIT_BOX_VERTICES * (hi - lo) + (lo + hi) / 2  # trimesh's box, scaled and moved
        self.vertices.append(vertices)
        self.faces.append(_UNIT_BOX_FACES + self.count)
        self.colors.append(np.tile(color, (len(vertices), 1)))
        self.count += len(vertices)


def _floor_tiles(b: _Builder, w: float, d: float, tile: float, colors: tuple[np.ndarray, np.ndarray]) -> None:
    """Checkerboard floor tiles as thin boxes whose top faces lie at y = 0."""
    nx, nz = int(np.ceil(w / tile)), int(np.ceil(d / tile))
    xs = np.linspace(-w / 2, w / 2, nx + 1)
    zs = np.linspace(-d / 2, d / 2, nz + 1)
    for i in range(nx):
        for j in range(nz):
            b.box([xs[i], -0.05, zs[j]], [xs[i + 1], 0.0, zs[j + 1]], colors[(i + j) % 2])


def _walls(b: _Builder, w: float, d: float, h: float, t: float, rng: np.random.Generator) -> None:
    """Four walls just outside the floor, each in three horizontal colour bands."""
    bands = [(0.0, 0.12), (0.12, h - 0.3), (h - 0.3, h)]
    colors = [_color(rng, val=(0.2, 0.5)), _color(rng, sat=(0.05, 0.4)), _color(rng, sat=(0.0, 0.2))]
    for (y0, y1), color in zip(bands, colors):
        b.box([-w / 2 - t, y0, -d / 2 - t], [w / 2 + t, y1, -d / 2], color)  # back
        b.box([-w / 2 - t, y0, d / 2], [w / 2 + t, y1, d / 2 + t], color)  # front
        b.box([-w / 2 - t, y0, -d / 2], [-w / 2, y1, d / 2], color)  # left
        b.box([w / 2, y0, -d / 2], [w / 2 + t, y1, d / 2], color)  # right


def _footprint(rng, w, d, size, taken: list[tuple[np.ndarray, np.ndarray]]) -> tuple | None:
    """A free (x, z) rectangle of ``size`` inside the room, or None after 50 tries."""
    for _ in range(50):
        cx = rng.uniform(-w / 2 + size[0] / 2, w / 2 - size[0] / 2)
        cz = rng.uniform(-d / 2 + size[1] / 2, d / 2 - size[1] / 2)
        lo, hi = np.array([cx, cz]) - size / 2, np.array([cx, cz]) + size / 2
        if all(np.any(hi <= a) or np.any(lo >= c) for a, c in taken):
            taken.append((lo - 0.05, hi + 0.05))
            return lo, hi
    return None


def procedural_room(seed: int, spec: RoomSpec | None = None) -> SceneMesh:
    """A furnished room drawn from ``seed`` (the same seed always gives the same room)."""
    spec = spec or RoomSpec()
    rng = np.random.default_rng(seed)
    w, d, h = rng.uniform(*spec.width), rng.uniform(*spec.depth), rng.uniform(*spec.height)
    b = _Builder()
    _floor_tiles(b, w, d, rng.uniform(*spec.tile), (_color(rng), _color(rng)))
    _walls(b, w, d, h, spec.wall_thickness, rng)
    t = spec.wall_thickness
    b.box(
        [-w / 2 - t, h, -d / 2 - t],
        [w / 2 + t, h + t, d / 2 + t],
        _color(rng, sat=(0.0, 0.1), val=(0.8, 1.0)),
    )
    taken: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(rng.integers(spec.num_boxes[0], spec.num_boxes[1] + 1)):
        size = rng.uniform([0.4, 0.4], [1.5, 1.2])
        spot = _footprint(rng, w, d, size, taken)
        if spot is not None:
            (x0, z0), (x1, z1) = spot
            b.box([x0, 0.0, z0], [x1, rng.uniform(0.4, 2.0), z1], _color(rng))
    for _ in range(rng.integers(spec.num_tables[0], spec.num_tables[1] + 1)):
        size = rng.uniform([0.6, 0.6], [1.8, 1.2])
        spot = _footprint(rng, w, d, size, taken)
        if spot is None:
            continue
        (x0, z0), (x1, z1) = spot
        top, leg, color = rng.uniform(0.7, 1.0), 0.06, _color(rng)
        b.box([x0, top - 0.04, z0], [x1, top, z1], color)
        for x, z in [(x0, z0), (x1 - leg, z0), (x0, z1 - leg), (x1 - leg, z1 - leg)]:
            b.box([x, 0.0, z], [x + leg, top - 0.04, z + leg], color)
    return make_scene(
        f"procedural-{seed}",
        np.concatenate(b.vertices),
        np.concatenate(b.faces),
        np.concatenate(b.colors),
        source=f"procedural room, seed {seed}, {w:.2f} x {d:.2f} x {h:.2f} m",
    )
