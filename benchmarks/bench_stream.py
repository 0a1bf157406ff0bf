"""Streaming cost of the live dance model: per-frame latency, frames per second, resident memory.

    python benchmarks/bench_stream.py --json
    python benchmarks/bench_stream.py --json --widths tiny --memory-minutes 1,10

For each backbone width (``paper``: recipes/backbones/skeleton_mamba.yaml; ``tiny``:
skeleton_mamba_tiny.yaml) the causal dance network (:class:`StreamDancer`, SMPL-24, random weights)
runs in a fresh subprocess with ``--threads`` torch threads under ``torch.inference_mode``:

- ``step``: one :meth:`StreamDancer.step` per 30 fps frame fed its own previous pose and a music
  feature row; median / p99 / max latency over ``--frames`` frames, and frames per second;
- ``windowed``: what a windowed model pays per new frame, re-running the same network's forward on
  the last ``--window`` frames (5 s) and keeping the last output; median over ``--window-repeats``;
- ``features``: the causal music features of one frame (:mod:`tasks.stream.features`, 44.1 kHz in);
- ``memory``: resident set size (VmRSS) after streaming ``--memory-minutes`` minutes of frames as
  fast as possible (synthetic features), and the size of the recurrent state.

The machine load (``os.getloadavg``) before and after is printed beside the figures: on a shared
machine the latencies are upper bounds; the ratios measured side by side are the robust part.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info  # noqa: E402

WIDTHS = {"paper": "skeleton_mamba.yaml", "tiny": "skeleton_mamba_tiny.yaml"}


def rss_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def build(width: str):
    import yaml

    from skeleton_mamba.recipes import __file__ as recipes_init
    from skeleton_mamba.tasks.backbone_config import backbone_config
    from skeleton_mamba.tasks.stream.model import StreamDancer

    fragment = Path(recipes_init).parent / "backbones" / WIDTHS[width]
    config = backbone_config(yaml.safe_load(fragment.read_text()))
    return StreamDancer(config).eval()


def measure(width: str, frames: int, window: int, window_repeats: int, minutes: list[float]) -> dict:
    """All figures of one width (run in a subprocess)."""
    import numpy as np
    import torch

    from skeleton_mamba.tasks.stream.features import CausalMusicFeatures
    from skeleton_mamba.tasks.stream.live import latency_summary

    torch.manual_seed(0)
    model = build(width)
    params = sum(p.numel() for p in model.parameters())
    music = torch.randn(1, 34)
    prev = torch.zeros(1, 24, 12)

    def run(count: int, state) -> list[float]:
        nonlocal prev
        times = []
        for _ in range(count):
            start = time.perf_counter()
            prev, state = model.step(prev, music, state)
            times.append(1e3 * (time.perf_counter() - start))
        return times

    with torch.inference_mode():
        state = model.init_state(1)
        run(10, state)  # warm-up
        step_ms = np.asarray(run(frames, state))
        history = torch.zeros(1, window, 24, 12)
        music_window = torch.randn(1, window, 34)
        model(history, music_window)
        windowed = []
        for _ in range(window_repeats):
            start = time.perf_counter()
            model(history, music_window)[:, -1]
            windowed.append(1e3 * (time.perf_counter() - start))
        extractor = CausalMusicFeatures(44100)
        audio = np.random.default_rng(0).standard_normal(44100 * 2).astype(np.float32) * 0.1
        hop = 44100 // 30
        extractor.push(audio[: 4 * hop])
        feature_ms = []
        for s in range(4 * hop, len(audio) - hop, hop):
            start = time.perf_counter()
            extractor.push(audio[s : s + hop])
            feature_ms.append(1e3 * (time.perf_counter() - start))
        memory = {}
        state = model.init_state(1)
        done = 0
        for m in sorted(minutes):
            target = int(round(m * 60 * 30))
            run(target - done, state)
            done = target
            memory[f"rss_mib_after_{m:g}_min"] = round(rss_mib(), 1)
    summary = latency_summary(step_ms)
    return {
        "width": width,
        "parameters": params,
        "threads": torch.get_num_threads(),
        "step": {
            **{k: round(v, 3) for k, v in summary.items()},
            "fps": round(1e3 / float(np.mean(step_ms)), 1),
            "frames": frames,
        },  # fmt: skip
        "windowed": {
            "window_frames": window,
            "median_ms_per_new_frame": round(float(np.median(windowed)), 2),
        },
        "features": {k: round(v, 3) for k, v in latency_summary(np.asarray(feature_ms)).items()},
        "memory": {**memory, "state_bytes": state.nbytes, "frames_streamed": done},
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--widths", default="paper,tiny")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--frames", type=int, default=300, help="frames timed per width")
    p.add_argument("--window", type=int, default=150, help="frames of the windowed baseline (5 s)")
    p.add_argument("--window-repeats", type=int, default=5)
    p.add_argument("--memory-minutes", default="1,10", help="minutes of music streamed before reading RSS")
    p.add_argument(
        "--omp-wait-policy",
        choices=("inherit", "passive", "active"),
        default="inherit",
        help="OMP_WAIT_POLICY of the measuring process (passive: idle threads sleep instead of spinning, "
        "which keeps 2 threads usable on a loaded machine)",
    )
    p.add_argument("--width-only", help=argparse.SUPPRESS)
    args = p.parse_args()
    minutes = [float(m) for m in args.memory_minutes.split(",")]
    if args.width_only:
        import torch

        torch.set_num_threads(args.threads)
        print(json.dumps(measure(args.width_only, args.frames, args.window, args.window_repeats, minutes)))
        return 0
    results = {
        "machine": machine_info(),
        "omp_wait_policy": args.omp_wait_policy
        if args.omp_wait_policy != "inherit"
        else os.environ.get("OMP_WAIT_POLICY", "default"),
        "load_before": [round(v, 2) for v in os.getloadavg()],
        "widths": {},
    }
    for width in args.widths.split(","):
        cmd = [sys.executable, __file__, "--width-only", width, "--threads", str(args.threads)]
        cmd += ["--frames", str(args.frames), "--window", str(args.window)]
        cmd += ["--window-repeats", str(args.window_repeats), "--memory-minutes", args.memory_minutes]
        env = dict(os.environ, OMP_NUM_THREADS=str(args.threads))
        if args.omp_wait_policy != "inherit":
            env["OMP_WAIT_POLICY"] = args.omp_wait_policy.upper()
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if proc.returncode:
            print(proc.stderr, file=sys.stderr)
            return proc.returncode
        results["widths"][width] = json.loads(proc.stdout.strip().splitlines()[-1])
    results["load_after"] = [round(v, 2) for v in os.getloadavg()]
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print(results["machine"])
    print(f"load (1/5/15 min) before {results['load_before']}, after {results['load_after']}")
    for width, r in results["widths"].items():
        s, w = r["step"], r["windowed"]
        print(
            f"{width:5s} {r['parameters'] / 1e6:6.2f} M params, {r['threads']} threads: step median "
            f"{s['median_ms']:.2f} ms, p99 {s['p99_ms']:.2f} ms, {s['fps']:.0f} fps | windowed "
            f"({w['window_frames']} frames) {w['median_ms_per_new_frame']:.1f} ms/frame | features "
            f"{r['features']['median_ms']:.2f} ms | {r['memory']}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
