"""Does the recognition data loader keep the training step fed?

Generated NTU-like data (60 classes, 300-frame sequences, 2 bodies, 25 joints) goes through the real
data module (PYSKL pipeline: pre-normalization, uniform sampling of ``clip_len`` frames) with
``num_workers`` worker processes, and a real optimizer step of the recognition model consumes it.
For every step we time the wait for the next batch and the step itself (forward, backward, SGD).
The loader keeps up when the mean wait is small against the mean step time.

    python benchmarks/bench_recognition_loader.py [--json] [--backbone tiny|paper] [--num-workers 2]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

from skeleton_mamba import MixerConfig, SkeletonMambaConfig  # noqa: E402
from skeleton_mamba.tasks.recognition.data import SyntheticRecognitionDataModule  # noqa: E402
from skeleton_mamba.tasks.recognition.module import ActionRecognitionModule  # noqa: E402

BACKBONES = {
    # One block of width 16: the cheapest step, the hardest case for the loader.
    "tiny": SkeletonMambaConfig(
        dim=16, depth=1, heads=2, mlp_dim=32, group_paths=[[1, 2, 0, 3, 4]],
        mixer=MixerConfig(d_state=16, headdim=8, chunk_size=16),
    ),
    "paper": SkeletonMambaConfig(),  # D 128, N 8, MLP 1024 (recipes/backbones/skeleton_mamba.yaml)
}  # fmt: skip


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def measure(
    backbone: str, num_workers: int, batch_size: int, clip_len: int, steps: int, warmup: int, device: str
) -> dict:
    """Mean / median batch wait and step time (ms) over ``steps`` steps after ``warmup`` steps."""
    torch.manual_seed(0)
    dm = SyntheticRecognitionDataModule(
        num_classes=60, train_per_class=4, val_per_class=1, num_frames=300, num_bodies=2,
        clip_len=clip_len, num_person=2, batch_size=batch_size, num_workers=num_workers,
    )  # fmt: skip
    dm.setup("fit")
    module = ActionRecognitionModule(
        backbone=BACKBONES[backbone], num_classes=60, skeleton=dm.skeleton, in_channels=dm.in_channels,
        batch_size=batch_size,
    )  # fmt: skip
    device = torch.device(device)
    module.to(device)
    optimizer = torch.optim.SGD(module.parameters(), lr=module.effective_lr(), momentum=0.9, nesterov=True)
    waits, step_times = [], []
    batches = iter(dm.train_dataloader())  # 240 samples: the loader is re-created when exhausted
    for i in range(warmup + steps):
        start = time.perf_counter()
        try:
            keypoint, label = next(batches)
        except StopIteration:
            batches = iter(dm.train_dataloader())
            keypoint, label = next(batches)
        keypoint, label = keypoint.to(device, non_blocking=True), label.to(device, non_blocking=True)
        _sync(device)
        ready = time.perf_counter()
        loss = F.cross_entropy(module.model(keypoint.flatten(0, 1)), label)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        _sync(device)
        done = time.perf_counter()
        if i >= warmup:
            waits.append((ready - start) * 1e3)
            step_times.append((done - ready) * 1e3)
    mean_wait, mean_step = statistics.mean(waits), statistics.mean(step_times)
    return {
        "backbone": backbone,
        "device": str(device),
        "num_workers": num_workers,
        "batch_size": batch_size,
        "clip_len": clip_len,
        "steps": steps,
        "mean_wait_ms": round(mean_wait, 2),
        "median_wait_ms": round(statistics.median(waits), 2),
        "mean_step_ms": round(mean_step, 2),
        "median_step_ms": round(statistics.median(step_times), 2),
        "wait_over_step": round(mean_wait / mean_step, 4),
        "fed": mean_wait < 0.1 * mean_step,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--backbone", choices=sorted(BACKBONES), default="tiny")
    parser.add_argument("--num-workers", type=int, default=2)
    parser.add_argument("--batch-size", type=int, default=16)
    parser.add_argument("--clip-len", type=int, default=100)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--threads", type=int, default=1, help="torch threads of the training process")
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    result = measure(
        args.backbone, args.num_workers, args.batch_size, args.clip_len, args.steps, args.warmup, args.device
    )
    result = {"machine": machine_info(), "torch_threads": args.threads, **result}
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:>16}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
