"""Benchmark the pure-PyTorch SSD (forward + backward) against its recurrence and causal SDPA.

Setting (defaults): 4 heads of width P = 64, state N = 64, one B/C group, fp32, 2 threads;
batch 192 at T = 150 and batch * T kept at 28,800 tokens for the other lengths (24 at 1200, 6 at 4800).
``sdpa_ms`` is ``torch.nn.functional.scaled_dot_product_attention(is_causal=True)`` with the same
heads, width and batch. ``max_abs_err`` compares ``ssd`` in fp32 with the float64 recurrence on
``--err-batch`` sequences of the same length (``max_rel_err`` divides it by max |y|, and
``fp32_recurrence_abs_err`` is the error of the fp32 recurrence itself, for scale). ``gemm`` is this
machine's fp32 matrix-product rate timed in the same process (before and after the rows), and each row
gives ``ssd_rate`` / ``sdpa_rate``: the matrix-product work of one forward + backward, the rate it ran at
and its fraction of the GEMM rate. ``finite_check_ms`` times the finiteness check ``ssd`` runs on its
inputs once per call (the fast path of ``skeleton_mamba/ssd/non_finite.py``); ``finite_check_share``
divides it by ``ssd_ms``. The recurrence
(one Python step per time step) is timed at the first length, and at later lengths only when the
per-step cost measured so far predicts less than ``--recurrence-budget-s``; otherwise it is null.
``ssd_ms`` and ``sdpa_ms`` are medians of ``--repeats`` runs taken in turn, after three untimed rounds.
As ``sm fit`` does, the run keeps the memory a step frees in the heap (``malloc_kept``:
``skeleton_mamba.runtime.allocator.keep_freed_memory``), so that every step does not fault in fresh pages;
``--default-malloc`` leaves glibc's defaults. ``--compile`` adds the SSD compiled by inductor
(``compiled_*``: compile seconds, median ms, error, ratios) in the same run.

    python benchmarks/bench_ssd.py --json
    python benchmarks/bench_ssd.py --lengths 150 --batch 64 --repeats 3
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from torch.utils.flop_counter import sdpa_backward_flop_count, sdpa_flop_count

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import alternate_ms, gemm_gflop_per_s, machine_info, matmul_gflop, median_ms, rate  # noqa: E402

from skeleton_mamba.runtime.allocator import keep_freed_memory  # noqa: E402
from skeleton_mamba.ssd import ssd, ssd_recurrence  # noqa: E402
from skeleton_mamba.ssd.non_finite import inputs_finite  # noqa: E402

HEADS, HEADDIM, STATE, GROUPS = 4, 64, 64, 1
TOKENS = 192 * 150
WARMUP_ROUNDS = 3


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


def sdpa_gflop(batch: int, T: int) -> float:
    """Forward + backward work of the SDPA row by torch's own formulas (``torch.utils.flop_counter``;
    its CPU kernel is not intercepted by the counter). Full T x T products, as the counter counts them."""
    shape = (batch, HEADS, T, HEADDIM)
    return (sdpa_flop_count(shape, shape, shape) + sdpa_backward_flop_count(shape, shape, shape, shape)) / 1e9


def compiled_columns(
    inp: dict,
    small: dict,
    y_ref: torch.Tensor,
    chunk_size: int,
    impl: str,
    repeats: int,
    ssd_ms: float,
    sdpa_ms: float,
) -> dict:
    """The SSD forward + backward compiled by inductor (``torch.compile``, static shapes): its compile time
    (the first call), median ms, ratios and error against the float64 recurrence."""
    compiled = torch.compile(functools.partial(ssd, chunk_size=chunk_size, impl=impl), dynamic=False)
    run = fwd_bwd(compiled, inp)
    start = time.perf_counter()
    run()
    compile_s = time.perf_counter() - start
    ms = median_ms(run, repeats=repeats)
    with torch.no_grad():
        err = (compiled(**small).double() - y_ref).abs().max().item()
    return dict(
        compiled_compile_s=round(compile_s, 1),
        compiled_ssd_ms=round(ms, 2),
        compiled_max_abs_err=err,
        sdpa_over_compiled_ssd=round(sdpa_ms / ms, 2),
        ssd_over_compiled_ssd=round(ssd_ms / ms, 2),
    )


def bench_row(
    T: int,
    batch: int,
    repeats: int,
    recurrence_budget_s: float,
    step_s: float | None,
    err_batch: int,
    chunk_size: int,
    impl: str,
    gemm: dict,
    compile: bool = False,
) -> tuple[dict, float | None]:
    """One row; ``step_s`` is the recurrence time per time step measured on an earlier row."""
    inp = make_inputs(batch, T)
    ssd_run = fwd_bwd(ssd, inp, chunk_size=chunk_size, impl=impl)
    sdpa_run = sdpa_fwd_bwd(batch, T)
    # side by side: SSD and SDPA alternate, after rounds that let the heap reach its steady size
    times = alternate_ms({"ssd": ssd_run, "sdpa": sdpa_run}, repeats=repeats, warmup=WARMUP_ROUNDS)
    ssd_ms, sdpa_ms = times["ssd"], times["sdpa"]
    check_ms = median_ms(lambda: inputs_finite(inp["x"], inp["dt"], inp["B"], inp["C"]), repeats=repeats)
    recurrence_ms = None
    # The recurrence is one Python step per time step; run it only when the cost measured on an
    # earlier row says it fits in the budget (it is never extrapolated into a reported number).
    # One step costs about the same for any batch here (many small operations), hence per step.
    if step_s is None or step_s * T <= recurrence_budget_s:
        recurrence_ms = median_ms(fwd_bwd(ssd_recurrence, inp), repeats=1, warmup=0)
        step_s = recurrence_ms / 1e3 / T
    small = make_inputs(err_batch, T, seed=1)
    with torch.no_grad():
        y = ssd(**small, chunk_size=chunk_size, impl=impl)
        y_ref = ssd_recurrence(**{k: v.double() for k, v in small.items()})
        y_rec32 = ssd_recurrence(**small)
    err = (y.double() - y_ref).abs().max().item()
    row = dict(
        T=T,
        batch=batch,
        ssd_ms=round(ssd_ms, 2),
        recurrence_ms=None if recurrence_ms is None else round(recurrence_ms, 2),
        sdpa_ms=round(sdpa_ms, 2),
        max_abs_err=err,
        max_rel_err=err / y_ref.abs().max().item(),
        fp32_recurrence_abs_err=(y_rec32.double() - y_ref).abs().max().item(),
        sdpa_over_ssd=round(sdpa_ms / ssd_ms, 2),
        finite_check_ms=round(check_ms, 3),
        finite_check_share=round(check_ms / ssd_ms, 4),
        recurrence_over_ssd=None if recurrence_ms is None else round(recurrence_ms / ssd_ms, 1),
        ssd_rate=rate(matmul_gflop(ssd_run), ssd_ms, gemm),
        sdpa_rate=rate(sdpa_gflop(batch, T), sdpa_ms, gemm),
    )
    if compile:
        row.update(compiled_columns(inp, small, y_ref, chunk_size, impl, repeats, ssd_ms, sdpa_ms))
    return row, step_s


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--lengths", type=int, nargs="+", default=[150, 1200, 4800])
    parser.add_argument(
        "--batch",
        type=int,
        nargs="+",
        default=None,
        help=f"batch per length (one value for all, or one per length); default {TOKENS} tokens / T",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="timed runs per median (after 1 warm-up); the recurrence runs once",
    )
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--chunk-size", type=int, default=64)
    parser.add_argument("--impl", default="torch", help="ssd impl (default: torch = auto without kernel)")
    parser.add_argument("--err-batch", type=int, default=2)
    parser.add_argument(
        "--recurrence-budget-s",
        type=float,
        default=40.0,
        help="skip the recurrence (null) where the cost measured at an earlier length "
        "predicts more than this many seconds",
    )
    parser.add_argument(
        "--default-malloc",
        action="store_true",
        help="leave glibc's malloc thresholds at their defaults (by default they are set as sm fit sets "
        "them: skeleton_mamba.runtime.allocator.keep_freed_memory)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--compile",
        action="store_true",
        help="also time the SSD compiled (torch.compile, inductor) in the same run",
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    malloc_kept = False if args.default_malloc else keep_freed_memory()
    batches = args.batch or [max(1, TOKENS // T) for T in args.lengths]
    if len(batches) == 1:
        batches = batches * len(args.lengths)
    if len(batches) != len(args.lengths):
        parser.error("--batch takes one value or one per length")
    gemm_before = gemm_gflop_per_s()
    rows, step_s = [], None
    for T, batch in zip(args.lengths, batches):
        row, step_s = bench_row(
            T,
            batch,
            args.repeats,
            args.recurrence_budget_s,
            step_s,
            args.err_batch,
            args.chunk_size,
            args.impl,
            gemm_before,
            args.compile,
        )
        rows.append(row)
        if not args.json:
            print(row, flush=True)
    gemm = {"before": gemm_before, "after": gemm_gflop_per_s()}
    if args.json:
        info = {"machine": machine_info(), "threads": args.threads, "malloc_kept": malloc_kept}
        print(json.dumps({**info, "gemm": gemm, "rows": rows}))
    else:
        print("gemm GFLOP/s before / after:", gemm_before["gflop_per_s"], gemm["after"]["gflop_per_s"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
