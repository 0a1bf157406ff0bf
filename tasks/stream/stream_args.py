"""The command line of ``sm stream`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import add_precision_argument, command_parser
from skeleton_mamba.tasks.motion.io.option_types import (
    MAX_WORKERS,
    file_name_option,
    image_size_option,
    int_option,
    real_option,
)
from skeleton_mamba.tasks.motion.io.output_folder import OVERWRITE_HELP
from skeleton_mamba.tasks.motion.retarget.rig_output import add_rig_arguments
from skeleton_mamba.tasks.training.threads import THREADS_HELP

__all__ = ["STREAM_BF16_ERROR", "build_parser"]

# The bf16 dance of a stream against the fp32 one (measured; the bound is tested).
STREAM_BF16_ERROR = (
    "Measured on a tiny random network: joints within 1.4 %% of the largest fp32 coordinate "
    "over a 2 s stream."
)

EXAMPLES = """examples:
  sm stream --ckpt runs/stream_dance_demo/version_0/checkpoints/last.ckpt --music song.wav --out live/
  sm stream --ckpt last.ckpt --music song.wav --out live/ --realtime      # paced like live music
  arecord -f S16_LE -r 44100 -c 1 -t wav | sm stream --ckpt last.ckpt --music - --out live/
  sm stream --task recognition --ckpt best.ckpt --skeleton sample.npy --out online/"""


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm stream",
        "Run a causal Skeleton Mamba frame by frame on a live input: a dance to music as it arrives "
        "(--task dance), or online action recognition of a skeleton stream (--task recognition).",
        EXAMPLES,
    )
    p.add_argument(
        "--task",
        choices=("dance", "recognition"),
        default="dance",
        help="dance (default: the options here) or recognition (online action recognition, whose options "
        "sm stream --task recognition --help lists)",
    )
    p.add_argument(
        "--ckpt", required=True, help="a checkpoint of stream_dance*.yaml or a causal recognition recipe"
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.add_argument(
        "--name",
        type=file_name_option,
        default=None,
        help="file stem (default: the music's / skeleton file's stem)",
    )
    p.add_argument("--music", help="dance: audio file, or - for a WAV stream on standard input")
    p.add_argument(
        "--raw-rate",
        type=int_option(8_000, 192_000, "a sample rate (Hz)"),
        default=None,
        help="with --music -: headerless s16le mono PCM at this rate",
    )
    p.add_argument("--realtime", action="store_true", help="pace the input at the music's rate")
    p.add_argument(
        "--chunk-ms",
        type=real_option(1.0, 10_000.0, "milliseconds"),
        default=20.0,
        help="audio chunk length in ms",
    )
    p.add_argument("--no-render", action="store_true", help="skip the mp4")
    add_rig_arguments(p)
    p.add_argument(
        "--render-size",
        type=image_size_option,
        default=(480, 352),
        help="video WIDTHxHEIGHT, multiples of 16 (default: 480x352)",
    )
    p.add_argument(
        "--skeleton", help="recognition: a skeleton file (NTU .skeleton, PYSKL-style .npy (T, J, C))"
    )
    p.add_argument(
        "--threads", type=int_option(1, MAX_WORKERS, "a thread count"), default=None, help=THREADS_HELP
    )
    p.add_argument(
        "--compile",
        action="store_true",
        help="compile the frame step with torch.compile first (about a minute at the paper width, needs a "
        "C++ compiler; 1.7x faster per frame there in our runs: real time on 2 cores); if it fails, a "
        "warning and the eager step",
    )
    add_precision_argument(p, STREAM_BF16_ERROR)
    p.add_argument(
        "--quantize",
        choices=("none", "int8"),
        default="none",
        help="dance: the dancer's Linear layers as PyTorch's dynamically quantized int8 Linear (int8 weights "
        "per output channel, each input quantized as it comes), eager and fp32 only (default: none)",
    )
    return p
