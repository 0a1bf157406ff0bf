"""Helpers shared by the benchmark scripts: machine description, median timing, the machine's GEMM rate."""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import torch


def machine_info() -> str:
    """A one-line description of the machine the figures come from."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    gpu = f", GPU {torch.cuda.get_device_name()}" if torch.cuda.is_available() else ""
    return f"{cpu}, {os.cpu_count()} logical cores{gpu}, torch {torch.__version__}, {platform.system()}"


def median_ms(fn: Callable[[], object], repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in milliseconds (synchronising CUDA when used)."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        if torch.cuda.is_available():
            torch.cuda.synchronize()
        start = time.perf_counter()
        fn()
        if torch.cuda.is_available():
            torch.cuda.synchronize()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)


def alternate_ms(fns: dict[str, Callable[[], object]], repeats: int, warmup: int = 1) -> dict[str, float]:
    """Median ms of each function, called in turn ``repeats`` times after ``warmup`` untimed rounds (so a
    change of load on a shared machine hits every function alike)."""
    times: dict[str, list[float]] = {k: [] for k in fns}
    for i in range(warmup + repeats):
        for k, fn in fns.items():
            start = time.perf_counter()
            fn()
            if i >= warmup:
                times[k].append(1e3 * (time.perf_counter() - start))
    return {k: statistics.median(v) for k, v in times.items()}


def gemm_gflop_per_s(
    sizes: tuple[int, ...] = (1024, 2048, 4096), repeats: int = 3, dtype: torch.dtype = torch.float32
) -> dict:
    """The machine's matrix-product rate in ``dtype`` (fp32 by default), timed in this process: the best
    median over square sizes.

    ``2 n^3`` floating-point operations per ``n x n @ n x n`` product (on the current device, with the
    current torch thread count). Report a model's rate as a fraction of ``gflop_per_s`` to see how far it
    is from what the machine can do.
    """
    device = "cuda" if torch.cuda.is_available() else "cpu"
    by_size = {}
    for n in sizes:
        a = torch.randn(n, n, device=device, dtype=dtype)
        b = torch.randn(n, n, device=device, dtype=dtype)
        ms = median_ms(lambda a=a, b=b: a @ b, repeats=repeats, warmup=1)
        by_size[str(n)] = round(2 * n**3 / (ms / 1e3) / 1e9, 1)
    best = max(by_size, key=by_size.get)
    return {
        "gflop_per_s": by_size[best],
        "size": int(best),
        "by_size": by_size,
        "threads": torch.get_num_threads(),
        "device": device,
        "dtype": str(dtype).removeprefix("torch."),
    }


def matmul_gflop(fn: Callable[[], object]) -> float:
    """Matrix-product work of one call of ``fn`` in GFLOP (``torch.utils.flop_counter``: mm, bmm, einsum,
    attention and convolutions, forward and backward; elementwise work is not counted)."""
    from torch.utils.flop_counter import FlopCounterMode

    with FlopCounterMode(display=False) as counter:
        fn()
    return counter.get_total_flops() / 1e9


def rate(gflop: float, ms: float, gemm: dict) -> dict:
    """Achieved GFLOP/s of ``gflop`` done in ``ms`` milliseconds, and its fraction of the GEMM rate."""
    achieved = gflop / (ms / 1e3)
    return {
        "gflop": round(gflop, 3),
        "gflop_per_s": round(achieved, 1),
        "fraction_of_gemm": round(achieved / gemm["gflop_per_s"], 3),
    }


# Matrix-product operators (the GEMM rate's work); the rest is element-wise work, copies and reductions.
GEMM_OPERATORS = (
    "aten::mm",
    "aten::addmm",
    "aten::bmm",
    "aten::baddbmm",
    "aten::baddbmm_",
    "mkldnn::_linear_pointwise",
    "aten::_scaled_dot_product_flash_attention_for_cpu",
)


def operator_profile(fn: Callable[[], object], rows: int = 25) -> tuple[str, float]:
    """``fn()`` once under ``torch.profiler``: the ``rows`` operators with the most self CPU time (a table)
    and the share of the self CPU time spent in matrix products (:data:`GEMM_OPERATORS`)."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU], record_shapes=True) as prof:
        fn()
    events = prof.key_averages()
    total = sum(e.self_cpu_time_total for e in events)
    gemm = sum(e.self_cpu_time_total for e in events if e.key in GEMM_OPERATORS)
    table = prof.key_averages(group_by_input_shape=True).table(
        sort_by="self_cpu_time_total", row_limit=rows, max_name_column_width=30, max_shapes_column_width=70
    )
    return table, gemm / max(total, 1e-9)


def write_report(script: str, report: dict, out: Path | None = None) -> Path:
    """Write ``report`` as the JSON beside ``script`` (``bench_x.py`` -> ``bench_x.json``), or at ``out``;
    print and return its path."""
    out = Path(script).with_suffix(".json") if out is None else Path(out)
    out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {out}")
    return out
