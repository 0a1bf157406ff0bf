"""The command line of ``sm make-ego`` (argparse only: ``--help`` imports neither torch nor the builder)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.egodance.builder.config import BuildConfig, default_workers
from skeleton_mamba.tasks.motion.commands.cli_options import add_quiet_argument, command_parser
from skeleton_mamba.tasks.motion.io.option_types import (
    MAX_FRAMES,
    MAX_IMAGE_SIZE,
    MAX_WORKERS,
    fps_option,
    int_option,
    real_option,
    seed_option,
)
from skeleton_mamba.tasks.motion.io.output_folder import OVERWRITE_HELP

__all__ = ["build_parser"]

SECONDS = real_option(0.0, 86_400.0, "seconds", low_open=True)
PIXELS = int_option(1, MAX_IMAGE_SIZE, "pixels")
METRES = real_option(-10.0, 10.0, "metres")

EXAMPLES = """examples:
  sm make-ego --motion aistpp/motions --scenes replica/ --scene-pattern '*/mesh.ply' --up-axis z \\
      --out ego_aistpp --music-dir aistpp/music
  sm make-ego --motion synthetic/ --scenes procedural --out ego_demo --workers 2
  sm make-ego --motion one.npz --scenes simple_room.glb --up-axis z --out tiny --width 32 --height 32"""


def build_parser() -> argparse.ArgumentParser:
    d = BuildConfig(out="")
    p = command_parser(
        "sm make-ego",
        "Build an EgoAIST++-style egocentric dance dataset ([EgoMusic] supp. Sec. 5): dance windows placed "
        "in 3D scenes (feet on the floor, little penetration), rendered from a camera between the eyes. "
        "Re-running the same command resumes an interrupted build.",
        EXAMPLES,
    )
    p.add_argument(
        "--motion", required=True, help="a motion file (.npz ours, .pkl AIST++) or a folder of them"
    )
    p.add_argument(
        "--scenes", default=d.scenes, help="'procedural', a scene mesh file, or a folder of meshes"
    )
    p.add_argument("--out", required=True, help="output folder (re-run to resume)")
    p.add_argument(
        "--scene-pattern",
        default=None,
        help="glob of the scene files under a --scenes folder (Replica: '*/mesh.ply'); default: all meshes",
    )
    p.add_argument("--up-axis", default=d.up_axis, choices=["x", "y", "z"], help="up axis of the scene files")
    p.add_argument(
        "--num-rooms",
        type=int_option(1, 10_000, "a room count"),
        default=d.num_rooms,
        help="procedural rooms to cycle through",
    )
    p.add_argument("--fps", type=fps_option, default=d.fps, help="frame rate of motion and frames")
    p.add_argument(
        "--window", type=SECONDS, default=d.window_s, dest="window_s", metavar="SECONDS", help="window length"
    )
    p.add_argument(
        "--stride",
        type=SECONDS,
        default=d.stride_s,
        dest="stride_s",
        metavar="SECONDS",
        help="window stride (default: the window length)",
    )
    p.add_argument("--width", type=PIXELS, default=d.width, help="image width in pixels")
    p.add_argument("--height", type=PIXELS, default=d.height, help="image height in pixels")
    p.add_argument(
        "--fov",
        type=real_option(0.0, 180.0, "degrees", low_open=True, high_open=True),
        default=d.fov,
        help="horizontal field of view in degrees",
    )
    p.add_argument(
        "--threshold",
        type=real_option(0.0, 1e6, "centimetres"),
        default=d.threshold,
        help="reject placements whose penetration score S_p (cm) is above this",
    )
    p.add_argument(
        "--max-attempts",
        type=int_option(1, 1_000_000, "an attempt count"),
        default=d.max_attempts,
        help="placements tried per window",
    )
    p.add_argument(
        "--min-view-hits",
        type=real_option(0.0, 1.0, "a share of rays"),
        default=d.min_view_hits,
        help="reject placements whose first camera view hits geometry on fewer rays than this share "
        "(feet beyond the floor are always rejected)",
    )
    p.add_argument(
        "--penetration-stride",
        type=int_option(1, MAX_FRAMES, "a frame stride"),
        default=d.penetration_stride,
        help="score every n-th frame only",
    )
    p.add_argument(
        "--seed", type=seed_option, default=d.seed, help="random seed of the placements and procedural rooms"
    )
    p.add_argument(
        "--frames",
        default=d.frame_format,
        choices=["mp4", "png"],
        dest="frame_format",
        help="RGB frame storage",
    )
    p.add_argument(
        "--camera-forward",
        type=METRES,
        default=d.camera_forward,
        help="eye offset forward of the head joint in metres",
    )
    p.add_argument(
        "--camera-up", type=METRES, default=d.camera_up, help="eye offset above the head joint in metres"
    )
    p.add_argument(
        "--smpl-model",
        default=None,
        help="SMPL model file (official SMPL_NEUTRAL.pkl / basicModel_*.pkl, or an .npz conversion): "
        "score penetration with the posed SMPL mesh instead of capsules along the bones",
    )
    p.add_argument("--music-dir", default=None, help="folder of AIST++ music (<music id>.wav) for meta.json")
    p.add_argument("--keep-ignored", action="store_true", help="keep AIST++ ignore-list sequences")
    p.add_argument(
        "--skip-bad", action="store_true", help="go on past corrupt motion files and list them at the end"
    )
    p.add_argument(
        "--workers",
        type=int_option(0, MAX_WORKERS, "a worker count"),
        default=default_workers(),
        help="worker processes",
    )
    p.add_argument(
        "--max-faces",
        type=int_option(1, 1_000_000_000, "a triangle count"),
        default=d.max_faces,
        help="the most triangles a scene file may hold (checked from its header before it is loaded)",
    )
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_quiet_argument(p, "progress bar")
    p.add_argument("-v", "--verbose", action="store_true", help="log every skipped window and cleanup")
    return p
