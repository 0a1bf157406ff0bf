"""The command line of ``sm analyze-music`` (argparse only: ``--help`` imports neither torch nor librosa)."""

from __future__ import annotations

import argparse
from pathlib import Path

from skeleton_mamba.tasks.motion.commands.cli_options import command_parser
from skeleton_mamba.tasks.motion.io.option_types import real_option

__all__ = ["build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm analyze-music",
        "Print the tempo (BPM) and beat times of an audio file and optionally save its "
        "35-d FACT/EDGE librosa features (envelope, 20 MFCC, 12 chroma, onset peaks, beats).",
    )
    p.add_argument("file", type=Path, help="audio file (wav, flac, ogg/opus, mp3, ...)")
    p.add_argument(
        "--fps",
        type=int,
        choices=(30, 60),
        default=60,
        help="feature frame rate (default 60, FACT's; 30 is EDGE's): the beats fall on this frame grid, so "
        "the tempo read from them can move by a fraction of a BPM between the two",
    )
    p.add_argument("--out", type=Path, default=None, help="save the (T, 35) features to this .npy file")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument(
        "--start-bpm",
        type=real_option(1.0, 1000.0, "a tempo (BPM)"),
        default=None,
        help="the beat tracker's tempo prior (default: librosa's estimate): given near half or double the "
        "detected tempo, the tracker follows that octave instead (the 'tempo octaves' line says when both "
        "are plausible)",
    )
    p.add_argument("--cache-dir", type=Path, default=None, help="feature cache folder")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the feature cache")
    return p
