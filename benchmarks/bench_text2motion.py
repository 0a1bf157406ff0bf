"""Text-to-motion costs: Skeleton Mamba vs an MDM-style transformer denoiser of equal size, and the metrics.

Usage::

    python benchmarks/bench_text2motion.py [--backbone tiny|paper] [--batch 4] [--frames 196]
        [--repeats 3] [--max-real-seconds 600] [--json]

For the Skeleton Mamba denoiser (:class:`TextToMotionDenoiser`) and an MDM-style transformer
(:class:`TransformerDenoiser`, 8 layers, 4 heads, feed-forward 2x, width chosen for the same parameter
count), in the same run:

- ``train_step_ms``: forward + backward + AdamW step on noised (batch, frames, 263) with random 384-d
  caption tokens (the MiniLM width; the frozen text encoder is not timed);
- ``guided_step_ms``: one classifier-free guided x0 prediction (two denoiser calls) for ONE motion of
  ``frames`` (196) frames;
- ``ddim50_s`` / ``ddpm1000_s``: wall time of generating one 196-frame motion with the shared samplers
  (DDIM 50 steps, ancestral DDPM over 1000 steps, guidance 2.5), measured for real when 50 (1000) guided
  steps are projected to take at most ``--max-real-seconds``; otherwise ``*_s_extrapolated`` =
  ``guided_step_ms`` x steps (keys say so).

Also: ``recover_from_ric`` on (batch, frames, 263), R-Precision and FID on 4,384 random 512-d pairs.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, median_ms  # noqa: E402

from skeleton_mamba import MixerConfig, SkeletonMambaConfig  # noqa: E402
from skeleton_mamba.tasks.motion.formats.humanml3d_features import recover_from_ric  # noqa: E402
from skeleton_mamba.tasks.text2motion.baseline import TransformerDenoiser, width_for_parameters  # noqa: E402
from skeleton_mamba.tasks.text2motion.metrics import RPrecision, embedding_fid  # noqa: E402
from skeleton_mamba.tasks.text2motion.model import (  # noqa: E402
    LengthMaskedDenoiser,
    TextCondition,
    TextToMotionDenoiser,
)
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, ddim_sample, ddpm_sample, guided_x0  # noqa: E402

TEXT_DIM = 384
GUIDANCE = 2.5
DENOISERS = ("skeleton_mamba", "mdm_transformer")

BACKBONES = {
    "tiny": SkeletonMambaConfig(
        dim=16,
        depth=1,
        heads=2,
        mlp_dim=32,
        group_paths=[[1, 2, 0, 3, 4]],
        mixer=MixerConfig(d_state=16, headdim=8, chunk_size=16),
    ),
    "paper": SkeletonMambaConfig(),  # D 128, 8 blocks, MLP 1024 ([EgoMusic] supp. Table 2)
}


def _condition(batch: int) -> TextCondition:
    return TextCondition(torch.randn(batch, 12, TEXT_DIM), torch.ones(batch, 12, dtype=torch.bool))


def time_denoiser(model: torch.nn.Module, args: argparse.Namespace, diffusion: GaussianDiffusion) -> dict:
    """Training-step and generation timings of one denoiser (see the module docstring)."""
    b, frames = args.batch, args.frames
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    x0, mask, cond = torch.randn(b, frames, 263), torch.ones(b, frames, dtype=torch.bool), _condition(b)

    def train_step() -> None:
        x_t, t, target = diffusion.training_pair(x0)
        loss = ((model(x_t, t, cond, mask) - target) ** 2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()

    model.train()
    result = {"parameters": sum(p.numel() for p in model.parameters())}
    result["train_step_ms"] = median_ms(train_step, args.repeats)
    model.eval()
    one_mask, one_cond = torch.ones(1, frames, dtype=torch.bool), _condition(1)

    denoiser = LengthMaskedDenoiser(model, one_mask)  # guidance: one call on a doubled batch
    x_one = torch.randn(1, frames, 263)

    def guided_step() -> None:
        with torch.no_grad():
            guided_x0(denoiser, x_one, torch.full((1,), 500), one_cond, GUIDANCE)

    result["guided_step_ms"] = median_ms(guided_step, args.repeats)
    shape = (1, frames, 263)
    common = dict(cond=one_cond, guidance_weight=GUIDANCE, generator=torch.Generator().manual_seed(0))
    runs = {
        "ddim50": (50, lambda: ddim_sample(diffusion, denoiser, shape, sampling_steps=50, eta=0.0, **common)),
        "ddpm1000": (1000, lambda: ddpm_sample(diffusion, denoiser, shape, **common)),
    }
    for name, (steps, run) in runs.items():
        projected = result["guided_step_ms"] * steps / 1e3
        if projected <= args.max_real_seconds:
            start = time.perf_counter()
            run()
            result[f"{name}_s"] = time.perf_counter() - start
        else:
            result[f"{name}_s_extrapolated"] = projected
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backbone", choices=sorted(BACKBONES), default="tiny")
    parser.add_argument("--batch", type=int, default=4, help="training batch")
    parser.add_argument("--frames", type=int, default=196)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--max-real-seconds", type=float, default=600.0, help="longest projected sampling run timed for real"
    )
    parser.add_argument(
        "--denoiser", choices=("both", *DENOISERS), default="both", help="time one denoiser only (long runs)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    torch.manual_seed(0)
    diffusion = GaussianDiffusion(1000)

    mamba = TextToMotionDenoiser(BACKBONES[args.backbone], text_dim=TEXT_DIM)
    target = sum(p.numel() for p in mamba.parameters())
    width = width_for_parameters(target, TEXT_DIM)
    transformer = TransformerDenoiser(TEXT_DIM, latent=width)
    models = {"skeleton_mamba": (mamba, {}), "mdm_transformer": (transformer, {"latent": width})}
    denoisers = {
        name: {**extra, **time_denoiser(model, args, diffusion)}
        for name, (model, extra) in models.items()
        if args.denoiser in ("both", name)
    }
    ratios = {}
    if len(denoisers) == 2:
        a, b = denoisers["skeleton_mamba"], denoisers["mdm_transformer"]
        ratios = {
            k: a[k] / b[k] for k in ("train_step_ms", "guided_step_ms", "ddim50_s") if k in a and k in b
        }

    features = torch.randn(args.batch, args.frames, 263, dtype=torch.float64) * 0.05
    text, motion = torch.randn(4384, 512), torch.randn(4384, 512)

    def r_precision() -> None:
        metric = RPrecision()
        metric.update(text, motion)
        metric.compute()

    other = {
        "recover_from_ric_ms": median_ms(lambda: recover_from_ric(features), args.repeats),
        "r_precision_4384_ms": median_ms(r_precision, args.repeats),
        "fid_4384x512_ms": median_ms(lambda: embedding_fid(text, motion), args.repeats),
    }
    report = {
        "machine": machine_info(),
        "threads": 1,
        "backbone": args.backbone,
        "train_batch": args.batch,
        "frames": args.frames,
        "repeats": args.repeats,
        "denoisers": denoisers,
        "mamba_over_transformer": ratios,
        "median_ms": other,
    }
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(f"{report['machine']} (1 thread); backbone {args.backbone}, {args.frames} frames")
        for name, values in denoisers.items():
            print(f"  {name}: " + ", ".join(f"{k} {v:.4g}" for k, v in values.items()))
        print("  mamba / transformer: " + ", ".join(f"{k} {v:.2f}x" for k, v in ratios.items()))
        for name, value in other.items():
            print(f"  {name:<24} {value:10.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
