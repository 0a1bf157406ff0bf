"""``sm dance``: estimate a dance with a trained EMM checkpoint and write it as our motion ``.npz``.

Examples::

    sm dance --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt \\
        --sample runs/egodance_demo/data/ego/samples/<id> --out dance.npz
    sm dance --ckpt last.ckpt --music song.wav --video ego.mp4 --out dance.npz --sampler ddpm

``--sample`` reads an EgoAIST++ sample folder (music slice, egocentric frames and the camera trajectory for
head guidance). ``--music`` (+ ``--video`` for vision models) dances a whole track: tracks longer than the
training window are sampled as overlapping windows kept consistent during sampling (EDGE long-form).
The output can be rendered with ``sm render`` or converted to BVH.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sm dance", description=__doc__.split("\n\n")[0])
    p.add_argument("--ckpt", required=True, help="an EgoDanceModule checkpoint (.ckpt)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--sample", help="an EgoAIST++ sample folder (sm make-ego)")
    src.add_argument("--music", help="an audio file")
    p.add_argument("--video", help="egocentric video for --music (needed by vision models)")
    p.add_argument("--out", required=True, help="output motion .npz")
    p.add_argument("--sampler", choices=("ddim", "ddpm"), default=None, help="default: the checkpoint's")
    p.add_argument("--steps", type=int, default=None, help="DDIM steps (default: the checkpoint's)")
    p.add_argument("--guidance", type=float, default=None, help="classifier-free guidance weight")
    p.add_argument("--head-weight", type=float, default=None, help="head guidance step size (0: off)")
    p.add_argument("--window", type=int, default=150, help="frames per window (training length)")
    p.add_argument("--overlap", type=int, default=75, help="overlap of long-form windows")
    p.add_argument("--no-ema", action="store_true", help="use the raw weights instead of the EMA")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    return p


def _conditions(args, module) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
    """music (T, L), frames (T, 3, S, S) or None, head targets (T, 3) or None."""
    from skeleton_mamba.tasks.egodance.builder.layout import read_frames
    from skeleton_mamba.tasks.egodance.data import EgoDanceDataset

    size = module.hparams.image_size
    vision = module.hparams.use_vision
    if args.sample:
        folder = Path(args.sample)
        num_frames = len(read_frames(folder)) if vision else None
        if num_frames is None:
            with np.load(folder / "camera.npz", allow_pickle=False) as cam:
                num_frames = len(cam["positions"])
        item = EgoDanceDataset([folder], window=num_frames, load_frames=vision, image_size=size)[0]
        return item["music"], item.get("frames"), item["head"]
    from skeleton_mamba.tasks.motion.music import extract_music_features

    music = torch.from_numpy(extract_music_features(args.music, fps=30).features.astype(np.float32))
    frames = None
    if vision:
        if not args.video:
            raise SystemExit(f"sm dance: {args.ckpt} conditions on egocentric video; pass --video")
        import imageio.v3 as iio
        import kornia

        rgb = torch.from_numpy(np.asarray(iio.imread(args.video))).permute(0, 3, 1, 2)
        n = min(len(rgb), len(music))
        music = music[:n]
        frames = kornia.geometry.transform.resize(rgb[:n].float() / 255.0, (size, size), antialias=True)
    return music, frames, None


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from skeleton_mamba.tasks.egodance.module import EgoDanceModule
    from skeleton_mamba.tasks.egodance.sampling import sample_long_dance, tokens_to_motion
    from skeleton_mamba.tasks.motion.motion_file import save_motion

    if not Path(args.ckpt).is_file():
        print(f"sm dance: checkpoint {args.ckpt} not found", file=sys.stderr)
        return 2
    module = EgoDanceModule.load_from_checkpoint(args.ckpt, map_location="cpu").eval()
    hp = module.hparams
    music, frames, head = _conditions(args, module)
    model = module.model if args.no_ema else module.ema.module
    tokens = sample_long_dance(
        model,
        module.diffusion,
        music,
        frames,
        head,
        window=args.window,
        overlap=args.overlap,
        sampler=args.sampler or hp.sampler,
        steps=args.steps or hp.sampling_steps,
        guidance_weight=hp.guidance_weight if args.guidance is None else args.guidance,
        head_weight=hp.head_guidance_weight if args.head_weight is None else args.head_weight,
        generator=torch.Generator().manual_seed(args.seed),
        progress=args.progress,
    )
    path = save_motion(args.out, tokens_to_motion(tokens))
    print(f"sm dance: {tokens.shape[0]} frames ({tokens.shape[0] / 30:.1f} s at 30 fps) -> {path}")
    return 0
