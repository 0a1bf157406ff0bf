"""Render speed: wall time per second of motion for ``render_motion`` (drawing alone and full mp4 / GIF).

Usage::

    python benchmarks/bench_render.py [--seconds 5] [--fps 30] [--repeats 3] [--json]

The motion is a synthetic SMPL-24 dance (sinusoidal joint rotations, drifting root) turned into
joints with the offset-table forward kinematics, rendered at 640x480.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, median_ms  # noqa: E402

from skeleton_mamba.skeletons import SMPL24  # noqa: E402
from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics_axis_angle  # noqa: E402
from skeleton_mamba.tasks.motion.render.skeleton import render_frames, render_motion  # noqa: E402


def synthetic_joints(seconds: float, fps: float) -> np.ndarray:
    """(T, 24, 3) joints of a smooth synthetic SMPL motion."""
    frames = round(seconds * fps)
    t = torch.arange(frames, dtype=torch.float64)[:, None, None] / fps
    phase = torch.rand(1, 24, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64) * 6
    poses = 0.4 * torch.sin(2 * torch.pi * 1.5 * t + phase)
    root = torch.stack([0.3 * torch.sin(t[:, 0, 0]), 0.9 + 0 * t[:, 0, 0], 0.2 * t[:, 0, 0]], dim=1)
    return smpl_forward_kinematics_axis_angle(poses, root).numpy()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="motion length")
    parser.add_argument("--fps", type=float, default=30.0, help="motion and video frame rate")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    joints = synthetic_joints(args.seconds, args.fps)
    names = SMPL24.joint_names
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        cases = {
            "draw_only": lambda: sum(1 for _ in render_frames(joints, SMPL24.parents, args.fps, names=names)),
            "mp4": lambda: render_motion(
                joints, SMPL24.parents, Path(tmp) / "b.mp4", args.fps, names=names, progress=False
            ),
            "gif": lambda: render_motion(
                joints, SMPL24.parents, Path(tmp) / "b.gif", args.fps, names=names, progress=False
            ),
        }
        for name, fn in cases.items():
            ms = median_ms(fn, repeats=args.repeats, warmup=1)
            results[name] = {
                "median_ms": round(ms, 1),
                "seconds_per_motion_second": round(ms / 1e3 / args.seconds, 4),
                "ms_per_frame": round(ms / len(joints), 2),
            }
    report = {
        "benchmark": "render",
        "machine": machine_info(),
        "motion_seconds": args.seconds,
        "fps": args.fps,
        "frames": len(joints),
        "size": "640x480",
        "threads": 1,
        "results": results,
    }
    if args.json:
        print(json.dumps(report))
    else:
        print(f"{report['machine']}; {len(joints)} frames ({args.seconds} s at {args.fps} fps), 640x480")
        for name, r in results.items():
            per_second, per_frame = r["seconds_per_motion_second"], r["ms_per_frame"]
            print(f"{name:10s} {per_second:.3f} s per second of motion ({per_frame} ms/frame)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
