"""SkeletonMamba vs its attention twin: forward+backward time, peak memory, parameters, scaling in T.

    python benchmarks/bench_backbone.py --json

Each measurement runs in a fresh subprocess so its peak memory (resident set high-water mark on
CPU, ``max_memory_allocated`` on CUDA) is its own. Each row also gives its matrix-product work per
forward + backward (``torch.utils.flop_counter``, recomputation under checkpointing included) and the rate
it ran at as a fraction of this machine's fp32 GEMM rate, timed in the parent process before and after the
rows (``gemm``). Prints one JSON object with ``--json``.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from attention_twin import AttentionTwin  # noqa: E402
from common import gemm_gflop_per_s, machine_info, matmul_gflop, median_ms  # noqa: E402

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig  # noqa: E402


def build(kind: str, dim: int, depth: int, checkpointing: bool) -> torch.nn.Module:
    if kind == "skeleton_mamba":
        cfg = SkeletonMambaConfig(
            skeleton="smpl24", in_channels=9, dim=dim, depth=depth, gradient_checkpointing=checkpointing
        )
        return SkeletonMamba(cfg)
    return AttentionTwin(9, 24, dim=dim, depth=depth)


def measure(
    kind: str, batch: int, length: int, dim: int, depth: int, repeats: int, threads: int, checkpointing: bool
) -> dict:
    """Forward+backward median time and peak memory of one model at one size (run in a subprocess)."""
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    device = "cuda" if torch.cuda.is_available() else "cpu"
    model = build(kind, dim, depth, checkpointing).to(device)
    x = torch.randn(batch, length, 24, 9, device=device)
    base_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    def step():
        model.zero_grad(set_to_none=True)
        model(x).square().mean().backward()

    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    ms = median_ms(step, repeats=repeats, warmup=1)
    if device == "cuda":
        peak_mb = torch.cuda.max_memory_allocated() / 2**20
    else:  # ru_maxrss is in KiB on Linux; the increase over the state before the first step
        peak_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base_rss) / 1024
    params = sum(p.numel() for p in model.parameters())
    gflop = matmul_gflop(step)
    return {
        "model": kind,
        "batch": batch,
        "T": length,
        "ms": round(ms, 1),
        "peak_mb": round(peak_mb, 1),
        "params": params,
        "gflop": round(gflop, 2),
        "gflop_per_s": round(gflop / (ms / 1e3), 1),
    }


def run_isolated(**kwargs) -> dict:
    args = [sys.executable, __file__, "--one", json.dumps(kwargs)]
    out = subprocess.run(args, capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"measurement {kwargs} failed (exit {out.returncode}):\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--batch", type=int, default=4, help="batch of the paper-configuration row")
    parser.add_argument("--scaling-batch", type=int, default=1, help="batch of the T-scaling rows")
    parser.add_argument("--lengths", type=int, nargs="+", default=[150, 600, 2400])
    parser.add_argument("--dim", type=int, default=128)
    parser.add_argument("--depth", type=int, default=8)
    parser.add_argument(
        "--scaling-depth",
        type=int,
        default=1,
        help="blocks in the T-scaling rows (time grows per block alike)",
    )
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--checkpointing",
        action="store_true",
        help="gradient checkpointing in SkeletonMamba (needed for the paper's size at batch 4 on 24 GB)",
    )
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(measure(**json.loads(args.one))))
        return 0

    torch.set_num_threads(args.threads)
    gemm_before = gemm_gflop_per_s()
    common = {
        "dim": args.dim,
        "depth": args.depth,
        "threads": args.threads,
        "checkpointing": args.checkpointing,
    }
    paper = [
        run_isolated(kind=k, batch=args.batch, length=150, repeats=args.repeats, **common)
        for k in ("skeleton_mamba", "attention_twin")
    ]
    scaling_common = {**common, "depth": args.scaling_depth}
    scaling = [
        run_isolated(
            kind=k, batch=args.scaling_batch, length=t, repeats=max(1, args.repeats - 1), **scaling_common
        )
        for t in args.lengths
        for k in ("skeleton_mamba", "attention_twin")
    ]
    gemm = {"before": gemm_before, "after": gemm_gflop_per_s()}
    for row in paper + scaling:
        row["fraction_of_gemm"] = round(row["gflop_per_s"] / gemm_before["gflop_per_s"], 3)
    growth = {}
    for kind in ("skeleton_mamba", "attention_twin"):
        times = {r["T"]: r["ms"] for r in scaling if r["model"] == kind}
        t0 = min(times)
        growth[kind] = {str(t): round(times[t] / times[t0], 2) for t in sorted(times)}
    result = {
        "machine": machine_info(),
        "threads": args.threads,
        "gemm": gemm,
        "config": common,
        "scaling_config": scaling_common,
        "paper_config": paper,
        "scaling": scaling,
        "growth_vs_shortest": growth,
    }
    if args.json:
        print(json.dumps(result))
    else:
        for row in paper + scaling:
            print(row)
        print("growth:", growth)
        print("gemm GFLOP/s before / after:", gemm_before["gflop_per_s"], gemm["after"]["gflop_per_s"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
