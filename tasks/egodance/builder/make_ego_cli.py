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

import logging
from pathlib import Path

from skeleton_mamba.tasks.egodance.builder import layout
from skeleton_mamba.tasks.egodance.builder.build import run_build
from skeleton_mamba.tasks.egodance.builder.config import BuildConfig
from skeleton_mamba.tasks.egodance.builder.make_ego_args import build_parser
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_folder, writing_outputs

__all__ = ["main", "build_parser"]


def main(argv: list[str]) -> int:
    """Entry point of ``sm make-ego``; returns the exit code."""
    args = vars(build_parser().parse_args(argv))
    motion = args.pop("motion")
    logging.basicConfig(
        level=logging.INFO if args.pop("verbose") else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    overwrite = args.pop("overwrite")
    cfg = BuildConfig(**args)
    # an earlier build (proven by the manifest sm make-ego signed) is resumed; any other folder is the user's
    own = ("build.json", "summary.json", layout.SAMPLES, layout.SKIPPED)
    claim_output_folder(cfg.out, "sm make-ego", own, overwrite=overwrite)
    layout.check_real_folders(cfg.out)
    created = not Path(cfg.out).exists()
    with writing_outputs(cfg.out, "sm make-ego", own):
        summary = run_build(cfg, motion, created=created)
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
