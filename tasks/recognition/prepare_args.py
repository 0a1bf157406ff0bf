"""The command line of ``sm prepare`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse
from pathlib import Path

from skeleton_mamba.tasks.motion.commands.cli_options import (
    SmHelpFormatter,
    add_quiet_argument,
    command_parser,
)
from skeleton_mamba.tasks.motion.io.option_types import MAX_WORKERS, int_option
from skeleton_mamba.tasks.recognition.pyskl import KEYPOINT_DTYPES

__all__ = ["build_parser"]


def build_parser() -> argparse.ArgumentParser:
    parser = command_parser(
        "sm prepare",
        "Build one PYSKL annotation pickle from raw NTU RGB+D or Kinetics-skeleton files.",
        "examples:\n  sm prepare ntu60 --raw nturgb+d_skeletons --out data/ntu60_3danno.pkl\n"
        "  sm prepare kinetics --raw kinetics-skeleton --out data/kinetics_2d.pkl",
    )
    sub = parser.add_subparsers(dest="dataset", required=True, metavar="{ntu60,ntu120,kinetics}")
    for name in ("ntu60", "ntu120", "kinetics"):
        source = (
            "ST-GCN's Kinetics-skeleton JSON (its train and val parts)"
            if name == "kinetics"
            else "raw NTU RGB+D .skeleton files (the benchmark splits; the known missing samples excluded)"
        )
        p = sub.add_parser(
            name,
            help=f"build the {name} annotation file",
            description=f"Build the {name} PYSKL annotation file from {source}.",
            formatter_class=SmHelpFormatter,
        )
        p.add_argument("--raw", type=Path, required=True, help="folder of the raw files")
        p.add_argument("--out", type=Path, required=True, help="annotation pickle to write")
        p.add_argument(
            "--workers",
            type=int_option(1, MAX_WORKERS, "a worker count"),
            default=2,
            help="parallel processes",
        )
        p.add_argument("--skip-bad", action="store_true", help="skip unreadable files with a warning")
        p.add_argument("--dtype", choices=KEYPOINT_DTYPES, default="float32",
                       help="keypoint storage (default: float32; float16 as PYSKL's own files)")  # fmt: skip
        if name == "kinetics":
            p.add_argument("--labels", type=Path, nargs="+",
                           help="label jsons (default: RAW/kinetics_{train,val}_label.json)")  # fmt: skip
        else:
            p.add_argument(
                "--max-bodies",
                type=int_option(1, 64, "a body count"),
                default=2,
                help="body slots per sample",
            )
        add_quiet_argument(p, "progress bar")
    return parser
