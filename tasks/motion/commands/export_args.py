"""The command line of ``sm export`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import command_parser
from skeleton_mamba.tasks.motion.formats.units import add_unit_arguments
from skeleton_mamba.tasks.motion.io.option_types import fps_option
from skeleton_mamba.tasks.motion.retarget.rig_output import add_rig_arguments

__all__ = ["build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm export", "Write a motion file as glTF 2.0 (.glb): a skinned skeleton and its animation."
    )
    p.add_argument(
        "motion",
        help="motion file: .npz (ours), .pkl (AIST++), .npy: (T,J,3) joints or (T,263) HumanML3D features, "
        ".bvh, .skeleton, .glb",
    )
    p.add_argument("--out", required=True, help="output .glb, in an existing folder")
    p.add_argument("--music", default=None, help="audio file: its first seconds are written beside as .wav")
    add_rig_arguments(p)
    p.add_argument("--skeleton", default=None, help="skeleton of a .npy joint file (smpl24, ntu25, ...)")
    p.add_argument(
        "--motion-fps", type=fps_option, default=None, help="input frame rate (overrides the file's)"
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="with --music / --rig: replace an existing .wav / rig file beside --out",
    )
    add_unit_arguments(p)
    return p
