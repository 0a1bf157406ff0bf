"""The command line of ``sm evaluate-dance`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse
from pathlib import Path

from skeleton_mamba.tasks.motion.commands.cli_options import add_quiet_argument, command_parser

__all__ = ["PROTOCOL_NAMES", "build_parser"]

# the named protocols of tasks/motion/metrics/protocols.py (PROTOCOLS), in its order (tests check both agree)
PROTOCOL_NAMES = ("fact", "bailando", "edge")


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm evaluate-dance",
        "FID_k/g, Div_k/g, BeatAlign (and PFC for edge) of generated dance under a named paper protocol.",
    )
    p.add_argument("generated", type=Path, help="folder of generated motions (.npz, AIST++ .pkl)")
    p.add_argument("real", type=Path, help="folder of real motions: the FID reference set")
    p.add_argument("--protocol", choices=PROTOCOL_NAMES, default="fact",
                   help="fact (FACT/QEAN, default), bailando or edge")  # fmt: skip
    p.add_argument(
        "--music-dir",
        type=Path,
        default=None,
        help="folder of the music, for BeatAlign: <music id>.wav of an AIST++ name in a motion's file name, "
        "else the audio file of the motion's stem",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    p.add_argument("--cache-dir", type=Path, default=None, help="music feature cache folder")
    add_quiet_argument(p)
    return p
