"""The command line of ``sm convert`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import command_parser

__all__ = ["build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = command_parser("sm convert", "HumanML3D features (T, 263) -> joint positions (T, 22, 3).")
    p.add_argument("features", help="(T, 263) .npy feature file")
    p.add_argument("--out", required=True, help="output .npy of joint positions (T, 22, 3), metres, y-up")
    p.add_argument("--normalized", action="store_true", help="the features are (x - Mean) / Std")
    p.add_argument("--stats", default=None, help="folder with Mean.npy and Std.npy (for --normalized)")
    return p
