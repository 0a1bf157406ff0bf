"""fp32 against bf16 autocast, side by side in one run: GEMM rates, the EMM guided step, the stream step.

    python benchmarks/bench_bf16.py [--size paper|tiny] [--repeats 5] [--json]

Reports the CPU's bf16 instruction flags (avx512_bf16, amx_*), the machine's fp32 and bf16 GEMM rates
(n x n matrix products, GFLOP/s), then for the EMM denoiser ([EgoMusic], the bench_egodance.py sizes; one
guided x0 call on T = 150 frames) and the streaming dancer (one frame step, the bench_stream.py widths)
the median time in fp32 and under ``torch.autocast(bfloat16)`` (what ``--precision bf16`` runs), measured
alternately in one loop so load on a shared machine hits both alike, and the bf16 output's largest
difference from the fp32 one relative to the largest fp32 value.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import warnings
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).parent))
from bench_egodance import SIZES, build  # noqa: E402
from bench_stream import build as build_dancer  # noqa: E402
from common import alternate_ms, machine_info  # noqa: E402

from skeleton_mamba.ssd.precision import inference_precision  # noqa: E402
from skeleton_mamba.tasks.training.diffusion.samplers import guided_x0  # noqa: E402


def cpu_bf16_flags() -> list[str]:
    """The bf16 matrix instruction flags /proc/cpuinfo lists (avx512_bf16, amx_bf16, amx_tile, ...)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return []
    return sorted(set(re.findall(r"\b(avx512_bf16|amx_[a-z0-9_]+)\b", text)))


def gemm_rates(n: int, repeats: int) -> dict[str, float]:
    """GFLOP/s of an n x n x n product in fp32 and bf16."""
    a32, b32 = torch.randn(n, n), torch.randn(n, n)
    a16, b16 = a32.bfloat16(), b32.bfloat16()
    ms = alternate_ms({"fp32": lambda: a32 @ b32, "bf16": lambda: a16 @ b16}, repeats)
    return {k: 2 * n**3 / (v * 1e-3) / 1e9 for k, v in ms.items()}


def relative_diff(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a.float() - b.float()).abs().max() / b.float().abs().max())


@torch.inference_mode()
def emm_step(size: str, repeats: int) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        emm = build(size)[0].eval()
    s = SIZES[size]["image_size"]
    music, frames = torch.randn(1, 150, 35), torch.rand(1, 150, 3, s, s)
    context = emm.encode_condition(music, frames)
    x, t = torch.randn(1, 150, 24, 10), torch.full((1,), 500, dtype=torch.long)

    def run(precision: str):
        with inference_precision(precision):
            return guided_x0(emm, x, t, context, 2.0)

    out = {p: run(p) for p in ("fp32", "bf16")}
    ms = alternate_ms({p: (lambda p=p: run(p)) for p in ("fp32", "bf16")}, repeats)
    return {"ms": ms, "speedup": ms["fp32"] / ms["bf16"], "rel_diff": relative_diff(out["bf16"], out["fp32"])}


@torch.inference_mode()
def stream_step(width: str, repeats: int, frames: int = 30) -> dict:
    model = build_dancer(width)
    music, prev = torch.randn(1, 34), torch.zeros(1, 24, 12)

    def run(precision: str):
        state, pose = model.init_state(1), prev
        with inference_precision(precision):
            for _ in range(frames):
                pose, state = model.step(pose, music, state)
        return pose

    out = {p: run(p) for p in ("fp32", "bf16")}
    ms = alternate_ms({p: (lambda p=p: run(p)) for p in ("fp32", "bf16")}, repeats)
    ms = {p: v / frames for p, v in ms.items()}  # per frame
    return {"ms": ms, "speedup": ms["fp32"] / ms["bf16"], "rel_diff": relative_diff(out["bf16"], out["fp32"])}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", choices=("paper", "tiny"), default="paper")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--gemm", type=int, default=1024, help="GEMM size n")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    result = {
        "machine": machine_info(),
        "cpu_bf16_flags": cpu_bf16_flags(),
        "gemm_gflops": gemm_rates(args.gemm, args.repeats),
        "emm_guided_step": emm_step(args.size, args.repeats),
        "stream_frame_step": stream_step(args.size, args.repeats),
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(result["machine"])
    print("bf16 CPU flags:", ", ".join(result["cpu_bf16_flags"]) or "none")
    g = result["gemm_gflops"]
    print(f"GEMM {args.gemm}^3: fp32 {g['fp32']:.0f} GFLOP/s, bf16 {g['bf16']:.0f} GFLOP/s")
    for name in ("emm_guided_step", "stream_frame_step"):
        r = result[name]
        print(f"{name} [{args.size}]: fp32 {r['ms']['fp32']:.2f} ms, bf16 {r['ms']['bf16']:.2f} ms "
              f"(fp32/bf16 {r['speedup']:.2f}x), bf16 max rel diff {r['rel_diff']:.2e}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
