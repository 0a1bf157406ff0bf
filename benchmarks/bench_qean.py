"""QEAN: autoregressive generation speed (plain vs fast) and one training step.

    python benchmarks/bench_qean.py --json    # [QEAN]'s size (hidden 800, 16 heads, 2/2/12 layers)
    python benchmarks/bench_qean.py --size tiny --frames 200

Generation runs ``--frames`` autoregressive steps for one sequence ([QEAN]'s protocol generates 1200; on a
CPU a few dozen steps give the per-frame rate) with :func:`generate_plain` and :func:`generate_fast` side by
side on the same model, and checks that both give the same frames. The training step is forward + backward
+ Adam on a batch of ``--batch`` windows ([QEAN]: 16). Prints one JSON object with ``--json``.
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

from skeleton_mamba.tasks.qean.generate import generate_fast, generate_plain  # noqa: E402
from skeleton_mamba.tasks.qean.model import QEAN, QEANConfig  # noqa: E402

SIZES = {
    "paper": QEANConfig(),
    # [QEAN]'s layer counts and sequence lengths at a width a CPU can time
    "narrow": QEANConfig(hidden=128, heads=4, mlp_dim=512),
    "tiny": QEANConfig(hidden=64, heads=4, motion_layers=1, audio_layers=1, cross_layers=2, mlp_dim=128),
}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", choices=sorted(SIZES), default="paper")
    p.add_argument("--frames", type=int, default=32, help="generated frames per timing")
    p.add_argument("--audio-chunk", type=int, default=32)
    p.add_argument("--batch", type=int, default=16, help="training batch")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    device = "cuda" if torch.cuda.is_available() else "cpu"
    torch.manual_seed(0)
    config = SIZES[args.size]
    model = QEAN(config).to(device).eval()
    seed = torch.randn(1, config.seed_frames, config.motion_dim, device=device)
    music = torch.randn(1, args.frames + config.music_frames, config.music_dim, device=device)

    plain_ms = median_ms(lambda: generate_plain(model, seed, music, args.frames), args.repeats, 1)
    fast_ms = median_ms(
        lambda: generate_fast(model, seed, music, args.frames, args.audio_chunk), args.repeats, 1
    )
    diff = (
        generate_plain(model, seed, music, args.frames) - generate_fast(model, seed, music, args.frames)
    ).abs()

    model.train()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-4)
    x = torch.randn(args.batch, config.seed_frames, config.motion_dim, device=device)
    z = torch.randn(args.batch, config.music_frames, config.music_dim, device=device)
    y = torch.randn(args.batch, config.predict_frames, config.motion_dim, device=device)

    def step() -> None:
        optimizer.zero_grad(set_to_none=True)
        torch.nn.functional.mse_loss(model(x, z), y).backward()
        optimizer.step()

    train_ms = median_ms(step, args.repeats, 1)
    result = {
        "benchmark": "qean",
        "machine": machine_info(),
        "threads": torch.get_num_threads(),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "size": args.size,
        "parameters_M": round(sum(p.numel() for p in model.parameters()) / 1e6, 2),
        "frames": args.frames,
        "generation_fps_plain": round(args.frames / (plain_ms / 1e3), 3),
        "generation_fps_fast": round(args.frames / (fast_ms / 1e3), 3),
        "fast_speedup": round(plain_ms / fast_ms, 3),
        "fast_vs_plain_max_abs_diff": float(diff.max()),
        "train_batch": args.batch,
        "train_step_ms": round(train_ms, 1),
        "repeats": args.repeats,
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for key, value in result.items():
            print(f"{key:>28}: {value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
