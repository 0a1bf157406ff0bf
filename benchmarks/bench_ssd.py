"""Benchmark the pure-PyTorch SSD (forward + backward) against its recurrence and causal SDPA.

Setting (defaults): 4 heads of width P = 64, state N = 64, one B/C group, fp32, 2 threads;
batch 192 at T = 150 and batch * T kept at 28,800 tokens for the other lengths (24 at 1200, 6 at 4800).
``sdpa_ms`` is ``torch.nn.functional.scaled_dot_product_attention(is_causal=True)`` with the same
heads, width and batch. ``max_abs_err`` compares ``ssd`` in fp32 with the float64 recurrence on
``--err-batch`` sequences of the same length.

    python benchmarks/bench_ssd.py --json
    python benchmarks/bench_ssd.py --lengths 150 --batch 64 --repeats 3
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, median_ms  # noqa: E402

from skeleton_mamba.ssd import ssd, ssd_recurrence  # noqa: E402

HEADS, HEADDIM, STATE, GROUPS = 4, 64, 64, 1
TOKENS = 192 * 150


def make_inputs(batch: int, T: int, dtype=torch.float32, seed: int = 0) -> dict[str, torch.Tensor]:
    """Inputs in the regime of an initialised Mamba-2 mixer (A in [-16, -1], Δ₀ in [0.001, 0.1])."""
    g = torch.Generator().manual_seed(seed)
    delta0 = torch.exp(torch.rand(HEADS, generator=g) * (math.log(0.1) - math.log(1e-3)) + math.log(1e-3))
    inp = dict(
        x=torch.randn(batch, T, HEADS, HEADDIM, generator=g),
        dt=torch.randn(batch, T, HEADS, generator=g),
        A=-torch.empty(HEADS).uniform_(1.0, 16.0, generator=g),
        B=torch.randn(batch, T, GROUPS, STATE, generator=g),
        C=torch.randn(batch, T, GROUPS, STATE, generator=g),
        D=torch.ones(HEADS),
        dt_bias=delta0 + torch.log(-torch.expm1(-delta0)),
    )
    return {k: v.to(dtype) for k, v in inp.items()}


def fwd_bwd(fn, inp: dict[str, torch.Tensor], **kw):
    """A closure running fn forward and backward with gradients for every input."""
    leaves = {k: v.clone().requires_grad_(True) for k, v in inp.items()}

    def run():
        for v in leaves.values():
            v.grad = None
        y = fn(**leaves, **kw)
        y.backward(torch.ones_like(y))

    return run


def sdpa_fwd_bwd(batch: int, T: int):
    q, k, v = (torch.randn(batch, HEADS, T, HEADDIM, requires_grad=True) for _ in range(3))

    def run():
        for t in (q, k, v):
            t.grad = None
        out = F.scaled_dot_product_attention(q, k, v, is_causal=True)
        out.backward(torch.ones_like(out))

    return run


def bench_row(T: int, batch: int, repeats: int, recurrence_max_tokens: int, err_batch: int,
              chunk_size: int, impl: str) -> dict:
    inp = make_inputs(batch, T)
    ssd_ms = median_ms(fwd_bwd(ssd, inp, chunk_size=chunk_size, impl=impl), repeats=repeats)
    sdpa_ms = median_ms(sdpa_fwd_bwd(batch, T), repeats=repeats)
    recurrence_ms = None
    if batch * T <= recurrence_max_tokens and T <= 1200:
        reps = repeats if T <= 200 else 1
        recurrence_ms = median_ms(fwd_bwd(ssd_recurrence, inp), repeats=reps, warmup=1 if T <= 200 else 0)
    small = make_inputs(err_batch, T, seed=1)
    with torch.no_grad():
        y = ssd(**small, chunk_size=chunk_size, impl=impl)
        y_ref = ssd_recurrence(**{k: v.double() for k, v in small.items()})
    err = (y.double() - y_ref).abs().max().item()
    return dict(T=T, batch=batch, ssd_ms=round(ssd_ms, 2),
                recurrence_ms=None if recurrence_ms is None else round(recurrence_ms, 2),
                sdpa_ms=round(sdpa_ms, 2), max_abs_err=err,
                ssd_vs_sdpa=round(sdpa_ms / ssd_ms, 2),
                ssd_vs_recurrence=None if recurrence_ms is None else round(recurrence_ms / ssd_ms, 1))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lengths", type=int, nargs="+", default=[150, 1200, 4800])
    parser.add_argument("--batch", type=int, nargs="+", default=None,
                        help="batch per length (one value for all, or one per length); "
                             f"default {TOKENS} tokens / T")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--chunk-size", type=int, default=64)
    parser.add_argument("--impl", default="torch", help="ssd impl (default: torch = auto without kernel)")
    parser.add_argument("--err-batch", type=int, default=2)
    parser.add_argument("--recurrence-max-tokens", type=int, default=TOKENS)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    batches = args.batch or [max(1, TOKENS // T) for T in args.lengths]
    if len(batches) == 1:
        batches = batches * len(args.lengths)
    if len(batches) != len(args.lengths):
        parser.error("--batch takes one value or one per length")
    rows = []
    for T, batch in zip(args.lengths, batches):
        row = bench_row(T, batch, args.repeats, args.recurrence_max_tokens, args.err_batch,
                        args.chunk_size, args.impl)
        rows.append(row)
        if not args.json:
            print(row, flush=True)
    if args.json:
        print(json.dumps({"machine": machine_info(), "threads": args.threads, "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
