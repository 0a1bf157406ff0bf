"""Text-to-motion costs: joint recovery, one training step, one guided sampling step, and the T2M metrics.

Usage::

    python benchmarks/bench_text2motion.py [--backbone tiny|seed] [--batch 8] [--frames 196] [--json]

- ``recover_from_ric``: (batch, frames, 263) features -> joints.
- ``train_step``: denoiser forward + backward + AdamW step on noised (batch, frames, 263) with
  random 384-d caption tokens (the MiniLM width; the text encoder itself is not timed).
- ``sample_step``: one classifier-free guided x0 prediction (two denoiser calls) for the batch;
  a 50-step DDIM run costs 50 of these, a DDPM run 1,000.
- ``r_precision`` / ``fid``: the metrics on 4,384 random 512-d embedding pairs (test-split size).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, median_ms  # noqa: E402

from skeleton_mamba import MixerConfig, SkeletonMambaConfig  # noqa: E402
from skeleton_mamba.tasks.diffusion import GaussianDiffusion, guided_x0  # noqa: E402
from skeleton_mamba.tasks.text2motion.features import recover_from_ric  # noqa: E402
from skeleton_mamba.tasks.text2motion.metrics import RPrecision, embedding_fid  # noqa: E402
from skeleton_mamba.tasks.text2motion.model import TextCondition, TextToMotionDenoiser  # noqa: E402

BACKBONES = {
    "tiny": SkeletonMambaConfig(
        dim=16, depth=1, heads=2, mlp_dim=32, group_paths=[[1, 2, 0, 3, 4]],
        mixer=MixerConfig(d_state=16, headdim=8, chunk_size=16),
    ),
    "seed": SkeletonMambaConfig(),  # D 128, 8 blocks, MLP 1024 (seed 000 Table 2)
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backbone", choices=sorted(BACKBONES), default="tiny")
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--frames", type=int, default=196)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    torch.manual_seed(0)
    b, frames = args.batch, args.frames

    features = torch.randn(b, frames, 263, dtype=torch.float64) * 0.05
    model = TextToMotionDenoiser(BACKBONES[args.backbone], text_dim=384)
    diffusion = GaussianDiffusion(1000)
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    x0 = torch.randn(b, frames, 263)
    mask = torch.ones(b, frames, dtype=torch.bool)
    cond = TextCondition(torch.randn(b, 12, 384), torch.ones(b, 12, dtype=torch.bool))

    def train_step() -> None:
        x_t, t, target = diffusion.training_pair(x0)
        loss = ((model(x_t, t, cond, mask) - target) ** 2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()

    def sample_step() -> None:
        with torch.no_grad():
            t = torch.full((b,), 500)
            guided_x0(lambda x, s, c: model(x, s, c, mask), x0, t, cond, 2.5)

    text, motion = torch.randn(4384, 512), torch.randn(4384, 512)

    def r_precision() -> None:
        metric = RPrecision()
        metric.update(text, motion)
        metric.compute()

    results = {
        "recover_from_ric_ms": median_ms(lambda: recover_from_ric(features), args.repeats),
        "train_step_ms": median_ms(train_step, args.repeats),
        "sample_step_ms": median_ms(sample_step, args.repeats),
        "r_precision_4384_ms": median_ms(r_precision, args.repeats),
        "fid_4384x512_ms": median_ms(lambda: embedding_fid(text, motion), args.repeats),
    }
    report = {
        "machine": machine_info(),
        "threads": 1,
        "backbone": args.backbone,
        "parameters": sum(p.numel() for p in model.parameters()),
        "batch": b,
        "frames": frames,
        "median_ms": results,
        "ddim50_seconds_per_batch": results["sample_step_ms"] * 50 / 1e3,
    }
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(f"{report['machine']} (1 thread); backbone {args.backbone}, batch {b} x {frames} frames")
        for name, value in results.items():
            print(f"  {name:<24} {value:10.1f} ms")
        print(f"  DDIM-50 per batch        {report['ddim50_seconds_per_batch']:10.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
