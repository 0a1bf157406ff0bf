"""The command line of ``sm ensemble`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse
import os

from skeleton_mamba.tasks.motion.commands.cli_options import command_parser
from skeleton_mamba.tasks.motion.io.option_types import real_option
from skeleton_mamba.tasks.motion.io.output_folder import OVERWRITE_HELP

__all__ = ["EXAMPLES", "build_parser"]

EXAMPLES = """examples:
  sm ensemble runs/ntu60_xsub/version_1 runs/ntu60_xsub_bone/version_1 --out runs/ensemble_jb
  sm ensemble J B JM BM --weights 2 2 1 1 --out runs/ensemble_4s   # PYSKL's four-stream fusion"""

MAX_WEIGHT = 1e6


def _problem(args: argparse.Namespace) -> str | None:
    """Why the options do not go together (a weight per run), or None."""
    if args.weights is not None and len(args.weights) != len(args.runs):
        return f"--weights: {len(args.weights)} weights for {len(args.runs)} runs (give one per run)"
    if args.weights is not None and not any(args.weights):
        return "--weights: at least one weight must be above 0"
    missing = [run for run in args.runs if not os.path.exists(run)]
    if missing:
        return f"{missing[0]}: no such run folder or score file"
    return None


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm ensemble",
        "Multi-stream action recognition, as PYSKL fuses its streams: the weighted sum of the class scores "
        "that sm test saved (scores.npz in each run's log dir) for the same samples of the same split; "
        "prints and writes top-1, top-5, mean class accuracy and the confusion matrix.",
        EXAMPLES,
    )
    p.add_argument(
        "runs",
        nargs="+",
        metavar="RUN",
        help="an sm test log dir holding scores.npz (or the file), one per stream",
    )
    p.add_argument(
        "--weights",
        nargs="+",
        type=real_option(0.0, MAX_WEIGHT, "a weight"),
        default=None,
        metavar="W",
        help="one weight per run, in the same order (default: 1 each; PYSKL's four streams j b jm bm: "
        "2 2 1 1)",
    )
    p.add_argument(
        "--score",
        choices=("prob", "logit"),
        default="prob",
        help="the scores added: the clip-averaged softmax PYSKL's tests dump, or the clip-averaged logits",
    )
    p.add_argument(
        "--out",
        default=None,
        help="folder for ensemble.json, ensemble_scores.npz and confusion_matrix.png / .csv "
        "(default: print only)",
    )
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.check(_problem)
    return p
