"""The command line of ``sm render`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.cli_options import add_quiet_argument, command_parser
from skeleton_mamba.tasks.motion.option_types import fps_option

__all__ = ["build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = command_parser("sm render", "Render a motion file as a skeleton animation (mp4 or gif).")
    p.add_argument("motion", help="motion file: .npz (ours), .pkl (AIST++), .npy (T,J,3), .bvh, .skeleton")
    p.add_argument("--out", required=True, help="output video, .mp4 or .gif")
    p.add_argument("--music", default=None, help="audio file muxed into the mp4 (cut to the motion's length)")
    p.add_argument("--fps", type=fps_option, default=None, help="output frame rate (default: the motion's)")
    p.add_argument("--skeleton", default=None, help="skeleton of a .npy joint file (smpl24, ntu25, ...)")
    p.add_argument(
        "--motion-fps", type=fps_option, default=None, help="input frame rate (overrides the file's)"
    )
    p.add_argument("--title", default=None, help="text drawn on every frame (default: the file name)")
    add_quiet_argument(p, "progress bar")
    return p
