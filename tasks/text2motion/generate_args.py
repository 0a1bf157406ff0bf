"""The command line of ``sm generate`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import (
    add_quiet_argument,
    command_parser,
)
from skeleton_mamba.tasks.motion.io.option_types import int_option, seed_option
from skeleton_mamba.tasks.motion.io.output_folder import OVERWRITE_HELP
from skeleton_mamba.tasks.motion.retarget.rig_output import add_rig_arguments
from skeleton_mamba.tasks.training.sampling_args import add_sampling_arguments

__all__ = ["build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = command_parser("sm generate", "Generate motion from text with a trained text-to-motion checkpoint.")
    p.add_argument(
        "--checkpoint",
        required=True,
        help="TextToMotionModule checkpoint (.ckpt), its export-pretrained folder or Hub id",
    )
    p.add_argument("--text", action="append", required=True, help="caption (repeat for several)")
    p.add_argument("--length", default="6s", help="duration: '6s' (20 fps) or a frame count (default: 6s)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.add_argument(
        "--num", type=int_option(1, 10_000, "a sample count"), default=1, help="samples per caption"
    )
    add_sampling_arguments(p)
    p.add_argument("--seed", type=seed_option, default=0, help="noise seed")
    p.add_argument("--render", choices=("gif", "mp4"), default=None, help="also render each motion")
    add_rig_arguments(p)
    add_quiet_argument(p, "progress bar")
    return p
