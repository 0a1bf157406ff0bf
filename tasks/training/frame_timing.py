"""What the live commands (``sm stream``: dance and online recognition) share: the checks before the first
frame, per-frame latency figures and the notices around compiling the frame step with ``torch.compile``.
"""

from __future__ import annotations

import os
import sys

import numpy as np
import torch

from skeleton_mamba.runtime.allocator import keep_freed_memory
from skeleton_mamba.tasks.training.pretrained import check_model_source

__all__ = ["announce_compile", "latency_summary", "prepare_live", "realtime_hint", "report_compile"]


def prepare_live(ckpt: str, threads: int | None) -> None:
    """Check the checkpoint, set the CPU threads and keep freed memory.

    A URL or a missing checkpoint is refused before any work; ``threads`` (None: torch's default) sets
    ``torch.set_num_threads``; the allocator keeps freed memory so that the per-frame path has no page faults.

    Raises:
        CheckpointError, OSError: the checkpoint is refused or missing (the message names it once; ``sm``
            prints it as one line, exit 2).
    """
    check_model_source(ckpt)  # a checkpoint file, a from_pretrained folder or a Hub id
    if threads:
        torch.set_num_threads(threads)
    keep_freed_memory()


def latency_summary(values_ms: np.ndarray) -> dict[str, float]:
    """Median, 99th percentile and maximum of per-frame times in ms (NaN when empty)."""
    if len(values_ms) == 0:
        return {"median_ms": float("nan"), "p99_ms": float("nan"), "max_ms": float("nan")}
    return {
        "median_ms": float(np.median(values_ms)),
        "p99_ms": float(np.percentile(values_ms, 99)),
        "max_ms": float(np.max(values_ms)),
    }


def announce_compile(enabled: bool, prog: str = "sm stream") -> bool:
    """Say, before it starts, that compiling takes a while; returns ``enabled``."""
    if enabled:
        print(
            f"{prog}: compiling the frame step with torch.compile (about a minute at the paper width)...",
            file=sys.stderr,
            flush=True,
        )
    return enabled


def report_compile(seconds: float | None, enabled: bool, prog: str = "sm stream") -> None:
    """The compile time, or nothing (not asked; or it failed and the warning said so)."""
    if enabled and seconds is not None:
        print(f"{prog}: frame step compiled in {seconds:.0f} s", file=sys.stderr)


def realtime_hint(
    latency: dict[str, float], compiled: bool, fps: float, threads: int | None = None, prog: str = "sm stream"
) -> str | None:
    """What to try when frames were late (p99 latency above one frame period); None when on time.

    The fixes, in the order they help on a busy machine: one intra-op thread (``threads``, default torch's
    count, above 1: ``--threads 1`` / ``OMP_NUM_THREADS=1``, with ``OMP_WAIT_POLICY=PASSIVE`` when the
    environment leaves the wait policy to OpenMP, :mod:`.threads`), then ``--compile`` when not compiled.
    None also when nothing is left to try, or without frames (NaN).
    """
    period_ms = 1e3 / fps
    if not latency["p99_ms"] > period_ms:
        return None
    threads = torch.get_num_threads() if threads is None else threads
    fixes = []
    if threads > 1:
        passive = "" if "OMP_WAIT_POLICY" in os.environ else " OMP_WAIT_POLICY=PASSIVE"
        fixes.append(
            f"it ran on {threads} threads: one thread (--threads 1, or OMP_NUM_THREADS=1{passive}) does not "
            "wait for threads that other jobs hold up"
        )
    if not compiled:
        fixes.append("--compile runs the frame step compiled (1.7x faster at the paper width)")
    if not fixes:
        return None
    return (
        f"{prog}: the p99 latency ({latency['p99_ms']:.0f} ms) is above one {fps:g} fps frame "
        f"({period_ms:.1f} ms): not real time on this machine; " + "; ".join(fixes)
    )
