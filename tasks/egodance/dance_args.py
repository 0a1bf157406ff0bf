"""The command line of ``sm dance`` (argparse only: ``--help`` and a missing input file answer before torch
or the checkpoint loads)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import (
    add_precision_argument,
    add_quiet_argument,
    command_parser,
)
from skeleton_mamba.tasks.motion.io.option_types import (
    MAX_FRAMES,
    file_name_option,
    image_size_option,
    int_option,
    real_option,
    seed_option,
)
from skeleton_mamba.tasks.motion.io.output_folder import OVERWRITE_HELP
from skeleton_mamba.tasks.motion.retarget.rig_output import add_rig_arguments
from skeleton_mamba.tasks.training.sampling_args import add_sampling_arguments

__all__ = ["DANCE_BF16_ERROR", "DEFAULT_BATCH_WINDOWS", "build_parser", "overlap_problem"]

# The bf16 dance against the fp32 one of the same seed (measured; the bound is tested).
DANCE_BF16_ERROR = (
    "Measured on a trained EgoMusic demo EMM (5 DDIM steps, 150 frames, same seed): joints within 6 mm "
    "of the fp32 dance (mean 0.3 mm)."
)

DEFAULT_BATCH_WINDOWS = 16
"""Windows of a long track denoised together (40 s of dance at the default 150 / 75 windows): memory is
bounded by this many windows whatever the track's length. Defined here, torch-free, for ``--help``;
:mod:`.sampling` takes it from here."""

EXAMPLES = """examples:
  sm dance --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt --list-samples
  sm dance --ckpt last.ckpt --sample runs/egodance_demo/data/ego/samples/<id> --out dance/
  sm dance --ckpt last.ckpt --music song.wav --video ego.mp4 --out dance/ --sampler ddpm"""


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm dance",
        "Estimate a dance with a trained EMM checkpoint from music (and egocentric video): writes the motion "
        "(.npz, .bvh) and an mp4 of the skeleton with the music. Tracks longer than a window are danced as "
        "overlapping windows, in-painted at every denoising step (EDGE long-form) or, for a model trained "
        "with inpaint_overlaps false (the demo's), each from its own conditions, joined by a cross-fade.",
        EXAMPLES,
    )
    p.add_argument(
        "--ckpt",
        required=True,
        help="an EgoDanceModule checkpoint (.ckpt), its sm export-pretrained folder or Hub id",
    )
    src = p.add_mutually_exclusive_group(required=True)
    p.input_path(
        src.add_argument(
            "--sample",
            help="an EgoAIST++ sample folder (sm make-ego): its music slice, egocentric frames, camera path",
        )
    )
    p.input_path(src.add_argument("--music", help="an audio file: dance the whole track"))
    src.add_argument(
        "--list-samples",
        action="store_true",
        help="print the held-out sample folders of the checkpoint's data (for --sample) and exit",
    )
    p.input_path(
        p.add_argument(
            "--video", help="egocentric video file or image folder for --music (models conditioned on video)"
        )
    )
    p.add_argument("--out", help="output folder (or FILE.npz: files named after FILE); required to dance")
    p.add_argument("--name", type=file_name_option, default="dance", help="file stem inside an output folder")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.add_argument("--no-render", action="store_true", help="write .npz and .bvh only")
    add_rig_arguments(p)
    p.add_argument(
        "--render-size",
        type=image_size_option,
        default=(640, 480),
        help="video WIDTHxHEIGHT, multiples of 16 (default: 640x480)",
    )
    add_sampling_arguments(p)
    p.add_argument(
        "--head-weight",
        type=real_option(0.0, 1e3, "a step size"),
        default=None,
        help="head guidance step size (0: off)",
    )
    p.add_argument(
        "--head",
        choices=("estimate", "oracle", "none"),
        default=None,
        help="head guidance targets: estimated from the video (default for vision models), the ground-truth "
        "camera path of a --sample (oracle), or none (default for music-only models)",
    )
    p.add_argument(
        "--heading",
        choices=("video", "none"),
        default="video",
        help="what holds each window's heading over a long track: the head's turns read from the egocentric "
        "video (default; models whose windows face their first heading), or none (the sampled motion's, "
        "which drifts over a minute)",
    )
    p.add_argument(
        "--fov",
        type=real_option(1.0, 179.0, "an angle in degrees"),
        default=90.0,
        help="the egocentric camera's horizontal field of view in degrees, for reading the head's turns from "
        "--video (default 90; a --sample's own camera is used)",
    )
    p.add_argument(
        "--window",
        type=int_option(1, MAX_FRAMES, "a frame count"),
        default=150,
        help="frames per window: the training length",
    )
    p.add_argument(
        "--overlap",
        type=int_option(0, MAX_FRAMES, "a frame count"),
        default=75,
        help="frames shared by consecutive long-form windows",
    )
    p.add_argument(
        "--inpaint",
        choices=("yes", "no"),
        default=None,
        help="in-paint each long-form window's overlap with the window before at every denoising step (EDGE) "
        "or not (each window from its own conditions, joined by the cross-fade); default: the checkpoint's "
        "inpaint_overlaps",
    )
    p.add_argument(
        "--batch-windows",
        type=int_option(1, 10_000, "a window count"),
        default=DEFAULT_BATCH_WINDOWS,
        help="long-form windows denoised together (memory is bounded by this many windows)",
    )
    p.add_argument("--no-ema", action="store_true", help="use the raw weights instead of the EMA")
    p.add_argument("--seed", type=seed_option, default=0, help="noise seed of the sampler")
    add_quiet_argument(p)
    p.add_argument(
        "--compile",
        action="store_true",
        help="run the denoiser compiled (torch.compile, weights frozen): about 2 minutes of CPU to compile "
        "at the paper size, then about 1.3 to 1.4x less time per step (measured; worth it for DDPM's "
        "1000 steps); same dance to float32 rounding",
    )
    add_precision_argument(p, DANCE_BF16_ERROR)
    p.check(overlap_problem)
    return p


def overlap_problem(args: argparse.Namespace) -> str | None:
    """Why ``--overlap`` does not fit ``--window``: consecutive long-form windows share at most half a window
    (the stitching's rule, ``tasks/training/diffusion/stitching.py``), so each frame lies in at most two."""
    if args.overlap > args.window // 2:
        return (
            f"--overlap {args.overlap}: consecutive windows share at most half of --window {args.window} "
            f"(at most {args.window // 2} frames)"
        )
    return None
