"""``sm dance``: estimate a dance with a trained EMM checkpoint; writes the motion (.npz, BVH) and an mp4.

Examples::

    sm dance --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt \\
        --sample runs/egodance_demo/data/ego/samples/<id> --out dance/
    sm dance --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt --list-samples
    sm dance --ckpt last.ckpt --music song.wav --video ego.mp4 --out dance/ --sampler ddpm

``--sample`` reads an EgoAIST++ sample folder (music slice, egocentric frames and the ground-truth camera
trajectory); ``--list-samples`` prints the held-out (test, then val) sample folders of the checkpoint's data,
one per line, which the model never saw in training. ``--head`` chooses the head-guidance targets:
``estimate`` (the default for vision models: the checkpoint's head-trajectory estimator on the egocentric
frames, what any video allows), ``oracle`` (the sample's ground-truth camera path; ``--sample`` only,
printed as oracle) or ``none``.
``--music`` (+ ``--video`` for vision models: a video file or a folder of images) dances a whole track:
tracks longer than the training window are sampled as overlapping windows whose overlaps are in-painted
at every denoising step (EDGE long-form), so a 60 s song gives one continuous dance.
``--out DIR`` receives ``<name>.npz`` (our motion format), ``<name>.bvh`` and ``<name>.mp4`` (the skeleton
with the music muxed in; ``--no-render`` skips it); ``--out FILE.npz`` names the files after FILE.
A checkpoint trained with ``canonicalize_init_head`` (the demo's) dances clips of at most one window: its
windows face their first frame's head heading, and long-form stitching joins windows in the world-yaw frame.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import sys
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.bounded_read import read_json
from skeleton_mamba.ssd.precision import PRECISION_HELP, PRECISIONS, inference_precision
from skeleton_mamba.tasks.egodance.builder.layout import read_frames
from skeleton_mamba.tasks.egodance.data import (
    EgoDanceDataModule,
    EgoDanceDataset,
    SyntheticEgoDanceDataModule,
)
from skeleton_mamba.tasks.egodance.export import write_dance
from skeleton_mamba.tasks.egodance.head_estimator import estimate_long_trajectory
from skeleton_mamba.tasks.egodance.module import EgoDanceModule
from skeleton_mamba.tasks.egodance.sampling import sample_long_dance
from skeleton_mamba.tasks.egodance.video_features import VideoFeatures, encode_video
from skeleton_mamba.tasks.motion.errors import InputError
from skeleton_mamba.tasks.motion.export import dance_files
from skeleton_mamba.tasks.motion.music import extract_music_features
from skeleton_mamba.tasks.motion.option_types import (
    MAX_FRAMES,
    image_size_option,
    int_option,
    real_option,
    seed_option,
)
from skeleton_mamba.tasks.motion.output_folder import (
    OVERWRITE_HELP,
    claim_output_files,
    claim_output_folder,
    record_outputs,
)
from skeleton_mamba.tasks.motion.render import RenderStyle
from skeleton_mamba.tasks.motion.value_checks import load_npz
from skeleton_mamba.tasks.training.diffusion.cli_options import add_sampling_arguments, sampling_overrides
from skeleton_mamba.tasks.training.pretrained import load_module_and_checkpoint_from

__all__ = ["main", "build_parser"]

# The bf16 dance against the fp32 one of the same seed (measured; the bound is tested).
DANCE_BF16_ERROR = (
    "Measured on a trained EgoMusic demo EMM (5 DDIM steps, 150 frames, same seed): joints within 6 mm "
    "of the fp32 dance (mean 0.3 mm)."
)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sm dance", description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--ckpt",
        required=True,
        help="an EgoDanceModule checkpoint (.ckpt), its sm export-pretrained folder or Hub id",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--sample", help="an EgoAIST++ sample folder (sm make-ego)")
    src.add_argument("--music", help="an audio file")
    src.add_argument(
        "--list-samples",
        action="store_true",
        help="print the held-out sample folders of the checkpoint's data (for --sample) and exit",
    )
    p.add_argument("--video", help="egocentric video file or image folder for --music (vision models)")
    p.add_argument("--out", help="output folder (or FILE.npz: files named after FILE); required to dance")
    p.add_argument("--name", default="dance", help="file stem inside an output folder")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.add_argument("--no-render", action="store_true", help="write .npz and .bvh only")
    p.add_argument(
        "--render-size", type=image_size_option, default=(640, 480), help="video WxH (multiples of 16)"
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
        "--window",
        type=int_option(1, MAX_FRAMES, "a frame count"),
        default=150,
        help="frames per window (training length)",
    )
    p.add_argument(
        "--overlap",
        type=int_option(0, MAX_FRAMES, "a frame count"),
        default=75,
        help="overlap of long-form windows",
    )
    p.add_argument("--no-ema", action="store_true", help="use the raw weights instead of the EMA")
    p.add_argument("--seed", type=seed_option, default=0)
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    p.add_argument(
        "--compile",
        action="store_true",
        help="run the denoiser compiled (torch.compile, weights frozen): about 2 minutes of CPU to compile "
        "at the paper size, then about 1.3 to 1.4x less time per step (measured; worth it for DDPM's "
        "1000 steps); same dance to float32 rounding",
    )
    p.add_argument(
        "--precision", choices=PRECISIONS, default="fp32", help=f"{PRECISION_HELP} {DANCE_BF16_ERROR}"
    )
    return p


def _music_source(args) -> tuple[str | None, float]:
    """The audio file and start time (s) the dance is sampled for."""
    if args.music:
        return args.music, 0.0
    meta = read_json(Path(args.sample) / "meta.json", error=InputError)
    music = meta.get("music") or {}
    return music.get("path"), float(music.get("start_s", 0.0))


def _denoiser(args, module) -> torch.nn.Module:
    """The EMM the dance is sampled with: the EMA weights, or the raw ones (``--no-ema``)."""
    return module.model if args.no_ema else module.ema.module


def _head_source(args, module) -> str:
    return args.head or ("estimate" if module.head_estimator is not None else "none")


def _conditions(
    args, module, canonical: bool = False
) -> tuple[torch.Tensor, torch.Tensor | VideoFeatures | None, torch.Tensor | None]:
    """music (T, L); frames (T, 3, S, S) (--sample), the video's per-frame features (--music --video) or
    None; ground-truth head targets (T, 3) (--sample) or None."""

    size = module.hparams.image_size
    vision = module.model.config.use_vision
    if args.sample:
        folder = Path(args.sample)
        num_frames = len(read_frames(folder)) if vision else None
        if num_frames is None:
            num_frames = len(load_npz(folder / "camera.npz")["positions"])
        item = EgoDanceDataset(
            [folder], window=num_frames, load_frames=vision, image_size=size, canonicalize_init_head=canonical
        )[0]
        return item["music"], item.get("frames"), item["head"]

    fps = module.hparams.get("fps", 30)  # the frame rate the model was trained at
    music = torch.from_numpy(extract_music_features(args.music, fps=fps).features.astype(np.float32))
    if not vision:
        return music, None, None
    if not args.video:
        raise InputError(f"{args.ckpt} conditions on egocentric video; pass --video")
    estimate = _head_source(args, module) == "estimate" and module.head_estimator is not None
    # decoded as a stream at the model's resolution, only as far as the music goes, and reduced to the
    # per-frame features of the vision encoder and the head estimator as it is read (in the dance's
    # precision, as the encoders would run inside the sampler)
    with inference_precision(args.precision):
        video = encode_video(
            Path(args.video),
            size,
            _denoiser(args, module).vision_encoder,
            module.head_estimator if estimate else None,
            window=args.window,
            max_frames=len(music),
            progress=args.progress,
        )
    n = video.num_frames  # at most len(music)
    if len(music) - n > 1:  # one frame of rounding between the two lengths is no news
        video_s, music_s = n / fps, len(music) / fps
        print(
            f"sm dance: warning: the video has {n} frames ({video_s:.1f} s at {fps:g} fps), "
            f"the music {len(music)} ({music_s:.1f} s); the dance covers the first {n / fps:.1f} s, "
            "where both are (pass a video as long as the music for the whole track)",
            file=sys.stderr,
        )
    return music[:n], video, None


def _head_targets(args, module, frames: torch.Tensor | VideoFeatures | None, oracle: torch.Tensor | None):
    """(head source, targets (T, 3) or None) as ``--head`` asks; exits with a message when impossible."""
    source = _head_source(args, module)
    if source == "oracle":
        if oracle is None:
            raise SystemExit("sm dance: --head oracle needs the ground-truth camera path of a --sample")
        return source, oracle
    if source == "estimate":
        if module.head_estimator is None or frames is None:
            raise SystemExit(
                f"sm dance: {args.ckpt} has no head-trajectory estimator (music-only); use --head none"
            )
        video = frames.head if isinstance(frames, VideoFeatures) else frames
        return source, estimate_long_trajectory(module.head_estimator.eval(), video, args.window)[0]
    return source, None


def _dance(args, module, music, frames, oracle) -> tuple[torch.Tensor, str]:
    """The dance tokens (T, 24, C) in fp32 and the head source, in the caller's precision region;
    ``frames`` (T, 3, S, S) or the video's :class:`VideoFeatures` (its z_v go to the sampler)."""
    head_source, head = _head_targets(args, module, frames, oracle)
    vision = None
    if isinstance(frames, VideoFeatures):
        frames, vision = None, frames.vision
    sampling = module.sampling.override(**sampling_overrides(args))
    tokens = sample_long_dance(
        _denoiser(args, module),
        module.diffusion,
        music,
        frames,
        head,
        window=args.window,
        overlap=args.overlap,
        vision=vision,
        **dataclasses.asdict(sampling),
        head_guidance_weight=module.head_guidance.weight if args.head_weight is None else args.head_weight,
        head_guidance_steps=module.head_guidance.steps,
        generator=torch.Generator().manual_seed(args.seed),
        progress=args.progress,
        compile=args.compile,
    )
    return tokens.float(), head_source


def held_out_samples(data_hparams: dict) -> dict[str, list[Path]]:
    """``test`` and ``val`` sample folders of the data a checkpoint was trained on, from its data module's
    hyper-parameters (the generated demo set when they have a ``count``, else an EgoAIST++ build)."""
    cls = SyntheticEgoDanceDataModule if "count" in data_hparams else EgoDanceDataModule
    accepted = inspect.signature(cls.__init__).parameters
    data = cls(**{k: v for k, v in data_hparams.items() if k in accepted})
    try:
        splits = data.split_folders()
    except FileNotFoundError as err:  # DatasetNotFoundError says what is missing and how to build it
        raise InputError(f"the checkpoint's data: {err}") from err
    return {split: splits[split] for split in ("test", "val") if splits[split]}


def _list_samples(ckpt: str, checkpoint: dict) -> int:
    data_hparams = checkpoint.get("datamodule_hyper_parameters") or {}
    if not data_hparams:
        raise InputError(f"{ckpt}: holds no data module hyper-parameters; its held-out samples are unknown")
    found = held_out_samples(data_hparams)
    if not found:
        raise InputError(f"{ckpt}: its data holds no held-out (test / val) sample")
    for split, folders in found.items():
        print(
            f"# {split}: {len(folders)} held-out samples (sm dance --ckpt {ckpt} --sample FOLDER --out DIR)"
        )
        print("\n".join(str(folder) for folder in folders))
    return 0


def claim_dance_output(out: str, name: str, render: bool, overwrite: bool) -> None:
    """``--out DIR``: a folder this command may write into; ``--out FILE.npz``: no file beside it replaced
    (:mod:`~skeleton_mamba.tasks.motion.output_folder`)."""
    path = Path(out)
    if path.suffix.lower() == ".npz":
        siblings = [path.with_name(name) for name in dance_files(path.stem, render)]
        claim_output_files(siblings, path, overwrite=overwrite)
    else:
        claim_output_folder(path, "sm dance", dance_files(name, render), overwrite=overwrite)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.list_samples and not args.out:
        parser.error("the following arguments are required: --out")
    if not args.no_render and (args.render_size[0] % 16 or args.render_size[1] % 16):
        raise InputError(f"--render-size {args.render_size[0]}x{args.render_size[1]}: use multiples of 16")
    if not args.list_samples:
        claim_dance_output(args.out, args.name, not args.no_render, args.overwrite)

    # checked: local, weights_only, project classes; read once
    module, checkpoint = load_module_and_checkpoint_from(EgoDanceModule, args.ckpt)
    if args.list_samples:
        return _list_samples(args.ckpt, checkpoint)
    module.eval()
    hp = module.hparams
    fps = hp.fps  # the frame rate the model was trained at (linked from its data module)
    data_hparams = checkpoint.get("datamodule_hyper_parameters") or {}
    canonical = bool(data_hparams.get("canonicalize_init_head", False))  # windows faced their first heading
    try:
        music, frames, oracle = _conditions(args, module, canonical)
    except ValueError as err:  # the music, video or sample files (their readers name the file)
        raise InputError(str(err)) from err
    if canonical and len(music) > args.window:
        raise InputError(
            f"{args.ckpt} was trained on windows turned to face their first frame's head heading "
            f"(canonicalize_init_head), which long-form stitching cannot join: give at most {args.window} "
            f"frames ({args.window / fps:.0f} s) of music and video, not {len(music)}"
        )
    if args.compile and args.precision != "fp32":
        raise InputError(
            f"--compile runs the denoiser in fp32 only: drop --compile or --precision {args.precision}"
        )
    with inference_precision(args.precision):
        tokens, head_source = _dance(args, module, music, frames, oracle)
    out = Path(args.out)
    out_dir, name = (out.parent, out.stem) if out.suffix.lower() == ".npz" else (out, args.name)
    width, height = args.render_size
    music_file, start_s = _music_source(args)
    if out.suffix.lower() != ".npz":
        record_outputs(out_dir, "sm dance", dance_files(name, not args.no_render))
    files = write_dance(
        tokens,
        out_dir,
        name,
        music=music_file,
        music_start_s=start_s,
        render=not args.no_render,
        style=RenderStyle(width=width, height=height),
        title=f"EMM {Path(args.ckpt).name}",
        progress=args.progress,
        fps=fps,
    )
    seconds = tokens.shape[0] / fps
    guidance = {
        "estimate": "head guidance from the head trajectory estimated from the video",
        "oracle": "head guidance from the ORACLE (ground-truth) camera path",
        "none": "no head guidance",
    }[head_source]
    print(f"sm dance: {guidance}")
    print(f"sm dance: {tokens.shape[0]} frames ({seconds:.1f} s at {fps:g} fps) written to", out_dir)
    print("\n".join(files.lines()))
    return 0
