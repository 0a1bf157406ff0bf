"""The command line of ``sm render`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import add_quiet_argument, command_parser
from skeleton_mamba.tasks.motion.formats.units import add_unit_arguments
from skeleton_mamba.tasks.motion.io.option_types import fps_option

__all__ = ["PREVIEW_FPS", "build_parser"]

PREVIEW_FPS = 30.0  # the default output rate of a faster motion


def build_parser() -> argparse.ArgumentParser:
    p = command_parser("sm render", "Render a motion file as a skeleton animation (mp4 or gif).")
    p.add_argument(
        "motion", help="motion file: .npz, .pkl (AIST++), .npy (T,J,3) or (T,263), .bvh, .skeleton, .glb"
    )
    p.add_argument("--out", required=True, help="output video, .mp4 or .gif, in an existing folder")
    p.add_argument("--music", default=None, help="audio file muxed into the mp4 (cut to the motion's length)")
    p.add_argument(
        "--fps",
        type=fps_option,
        default=None,
        help=f"output frame rate (default: the motion's, at most {PREVIEW_FPS:g}; frames are resampled)",
    )
    p.add_argument("--skeleton", default=None, help="skeleton of a .npy joint file (smpl24, ntu25, ...)")
    p.add_argument(
        "--motion-fps", type=fps_option, default=None, help="input frame rate (overrides the file's)"
    )
    p.add_argument("--title", default=None, help="text drawn on every frame (default: the file name)")
    add_quiet_argument(p, "progress bar")
    add_unit_arguments(p)
    return p
