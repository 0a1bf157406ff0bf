"""``sm make-ego``: build an EgoAIST++-style egocentric dance dataset ([EgoMusic] supp. Sec. 5).

Examples::

    sm make-ego --motion aistpp/motions --scenes replica/ --scene-pattern '*/mesh.ply' --up-axis z
        --out ego_aistpp --music-dir aistpp/music
    sm make-ego --motion synthetic/ --scenes procedural --out ego_demo --workers 2
    sm make-ego --motion one.npz --scenes simple_room.glb --up-axis z --out tiny --width 32 --height 32
    sm make-ego --motion aistpp/motions --scenes procedural --out ego_mesh --smpl-model SMPL_NEUTRAL.pkl

Re-running the same command resumes an interrupted build. The output layout is documented in
``skeleton_mamba/tasks/egodance/builder/layout.py``.
"""

from __future__ import annotations

import argparse
import logging

from skeleton_mamba.tasks.egodance.builder.build import BuildConfig, default_workers, run_build
from skeleton_mamba.tasks.motion.errors import InputError

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    d = BuildConfig(out="")
    p = argparse.ArgumentParser(
        prog="sm make-ego",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
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
    p.add_argument("--num-rooms", type=int, default=d.num_rooms, help="procedural rooms to cycle through")
    p.add_argument("--fps", type=float, default=d.fps, help="frame rate of motion and frames")
    p.add_argument("--window", type=float, default=d.window_s, dest="window_s", help="window length (s)")
    p.add_argument(
        "--stride",
        type=float,
        default=d.stride_s,
        dest="stride_s",
        help="window stride (s); default: the window length",
    )
    p.add_argument("--width", type=int, default=d.width, help="image width (pixels)")
    p.add_argument("--height", type=int, default=d.height, help="image height (pixels)")
    p.add_argument("--fov", type=float, default=d.fov, help="horizontal field of view (degrees)")
    p.add_argument(
        "--threshold", type=float, default=d.threshold, help="reject placements with S_p above (cm)"
    )
    p.add_argument("--max-attempts", type=int, default=d.max_attempts, help="placements tried per window")
    p.add_argument(
        "--min-view-hits",
        type=float,
        default=d.min_view_hits,
        help="reject placements whose first camera view hits geometry on fewer rays than this share "
        "(feet beyond the floor are always rejected)",
    )
    p.add_argument(
        "--penetration-stride", type=int, default=d.penetration_stride, help="score every n-th frame only"
    )
    p.add_argument("--seed", type=int, default=d.seed, help="random seed (placements, procedural rooms)")
    p.add_argument(
        "--frames",
        default=d.frame_format,
        choices=["mp4", "png"],
        dest="frame_format",
        help="RGB frame storage",
    )
    p.add_argument(
        "--camera-forward",
        type=float,
        default=d.camera_forward,
        help="eye offset forward of the head joint (m)",
    )
    p.add_argument("--camera-up", type=float, default=d.camera_up, help="eye offset above the head joint (m)")
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
    p.add_argument("--workers", type=int, default=default_workers(), help="worker processes")
    p.add_argument("--no-progress", action="store_false", dest="progress", help="hide the progress bar")
    p.add_argument("-v", "--verbose", action="store_true", help="log every skipped window and cleanup")
    return p


def main(argv: list[str]) -> int:
    """Entry point of ``sm make-ego``; returns the exit code."""
    args = vars(build_parser().parse_args(argv))
    motion = args.pop("motion")
    logging.basicConfig(
        level=logging.INFO if args.pop("verbose") else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    cfg = BuildConfig(**args)
    if not 0.0 <= cfg.min_view_hits <= 1.0:
        raise InputError(f"--min-view-hits {cfg.min_view_hits:g}: a share of rays, from 0 to 1")
    summary = run_build(cfg, motion)
    print(
        f"make-ego: {summary.planned} windows planned; this run placed {summary.placed}, "
        f"rejected {summary.rejected} placements, skipped {summary.skipped} windows; "
        f"{summary.already_complete} were already complete, {summary.already_skipped} already skipped; "
        f"{summary.complete} complete samples in {cfg.out}"
        + (f"; rebuilt {summary.rebuilt} damaged samples" if summary.rebuilt else "")
    )
    if summary.rejected:
        reasons = {"penetration": "penetrated the scene", "feet": "feet beyond the floor",
                   "view": "first view mostly empty"}  # fmt: skip
        counts = ", ".join(f"{n} {reasons.get(why, why)}" for why, n in summary.rejections.items() if n)
        print(f"make-ego: rejected placements: {counts}")
    if summary.bad_inputs:
        print(f"make-ego: skipped {len(summary.bad_inputs)} corrupt motion files:")
        print("\n".join(f"  {message}" for message in summary.bad_inputs))
    return 0
