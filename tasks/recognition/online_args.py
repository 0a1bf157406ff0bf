"""The command line of ``sm stream --task recognition`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import add_precision_argument, command_parser
from skeleton_mamba.tasks.motion.io.option_types import MAX_WORKERS, file_name_option, int_option
from skeleton_mamba.tasks.motion.io.output_folder import OVERWRITE_HELP
from skeleton_mamba.tasks.training.threads import THREADS_HELP

__all__ = ["ONLINE_BF16_ERROR", "build_parser"]

# The bf16 probabilities against the fp32 ones (measured; the bound is tested).
ONLINE_BF16_ERROR = "Measured on a tiny causal recognizer: probabilities within 5e-4 of fp32 over 30 frames."


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm stream --task recognition",
        "Online action recognition of a skeleton stream: the class probabilities after every frame (a .csv "
        "table and a plot) with a causal recognizer.",
    )
    p.add_argument("--task", choices=("recognition",), default="recognition", help=argparse.SUPPRESS)
    p.add_argument("--ckpt", required=True, help="a checkpoint of a causal recognition recipe")
    p.add_argument(
        "--skeleton",
        required=True,
        help="an NTU RGB+D .skeleton file (normalised as in training), or a .npy of keypoints (T, J, C) or "
        "(M, T, J, C) already in the model's input convention",
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument(
        "--name", type=file_name_option, default=None, help="file stem (default: the skeleton file's stem)"
    )
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.add_argument(
        "--threads", type=int_option(1, MAX_WORKERS, "a thread count"), default=None, help=THREADS_HELP
    )
    p.add_argument("--compile", action="store_true", help="compile the frame step with torch.compile first")
    add_precision_argument(p, ONLINE_BF16_ERROR)
    return p
