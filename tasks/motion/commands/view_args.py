"""The command line of ``sm view`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import command_parser
from skeleton_mamba.tasks.motion.formats.units import add_unit_arguments
from skeleton_mamba.tasks.motion.io.option_types import fps_option

__all__ = ["build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm view", "Write a self-contained HTML viewer of motions (opens from disk, no network)."
    )
    p.add_argument(
        "motions",
        nargs="+",
        help="motion files: .npz, .pkl, .bvh, .npy (T,J,3) or (T,263), .skeleton, .glb; a skinned character "
        ".glb / .vrm (sm retarget's output) is drawn with its own meshes",
    )
    p.add_argument("--out", required=True, help="output .html, in an existing folder")
    p.add_argument("--music", default=None, help="audio file played in sync (.wav, .mp3, .ogg, .flac)")
    p.add_argument("--metrics", default=None, help="a JSON file of metrics to list (e.g. demo.json)")
    p.add_argument("--overlay", action="store_true", help="draw the motions on top of one another")
    p.add_argument("--skeleton", default=None, help="skeleton of .npy joint files (smpl24, ntu25, ...)")
    p.add_argument(
        "--motion-fps", type=fps_option, default=None, help="input frame rate (overrides the files')"
    )
    add_unit_arguments(p)
    return p
