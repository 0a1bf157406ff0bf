"""The options of a dataset build (``sm make-ego``): :class:`BuildConfig` and the defaults it takes from the
builder's checks (:data:`MAX_SCENE_FACES` of :mod:`.scene_check`, :data:`MIN_VIEW_HITS` of
:mod:`.placement_checks`), plain Python so that the command's ``--help`` shows them without importing the
builder, torch or numpy."""

from __future__ import annotations

from dataclasses import dataclass

from skeleton_mamba.tasks.training.threads import available_cores

__all__ = ["MAX_SCENE_FACES", "MIN_VIEW_HITS", "BuildConfig", "default_workers"]

MAX_SCENE_FACES = 5_000_000  # triangles of one scene: ray cast at every frame (the sample room has 84)

# Share of the first frame's rays that must hit geometry (:mod:`.placement_checks`): a closed room seen from
# inside gives 1.0; an open scene (simple_room.glb: a floor, one wall, a table) seen from its floor 0.2 to
# 0.6; a camera at the floor's edge facing the void under 0.1 (measured over 40 random placements of a
# synthetic dance there).
MIN_VIEW_HITS = 0.2


def default_workers() -> int:
    """Worker processes by default: the CPUs this process may use."""
    return max(1, available_cores())


@dataclass
class BuildConfig:
    """Options of ``sm make-ego`` (see ``make_ego_args.py`` for their help)."""

    out: str
    scenes: str = "procedural"
    up_axis: str = "y"
    scene_pattern: str | None = None  # glob under a scenes folder, e.g. "*/mesh.ply" for Replica
    num_rooms: int = 8
    fps: float = 30.0
    window_s: float = 5.0
    stride_s: float | None = None  # None: the window length (non-overlapping windows)
    width: int = 224
    height: int = 224
    fov: float = 90.0
    threshold: float = 2.0
    max_attempts: int = 20
    min_view_hits: float = MIN_VIEW_HITS  # share of the first frame's rays that must hit geometry
    penetration_stride: int = 1
    seed: int = 0
    frame_format: str = "mp4"
    camera_forward: float = 0.10
    camera_up: float = 0.06
    smpl_model: str | None = None  # SMPL model file (.pkl official / .npz): score the mesh, not capsules
    music_dir: str | None = None
    keep_ignored: bool = False
    skip_bad: bool = False  # go on past corrupt motion files and list them at the end
    workers: int = 1
    progress: bool = True
    max_faces: int = MAX_SCENE_FACES  # triangles a scene file may hold (checked before it is loaded)

    @property
    def stride(self) -> float:
        """Window stride in seconds (the window length unless set)."""
        return self.window_s if self.stride_s is None else self.stride_s
