"""Streaming cost of the live dance model: per-frame latency, frames per second, resident memory.

    python benchmarks/bench_stream.py --json
    python benchmarks/bench_stream.py --json --widths tiny --memory-minutes 1,10
    python benchmarks/bench_stream.py --json --compile     # + the step compiled with torch.compile
    python benchmarks/bench_stream.py --json --onnx        # + the dancer's step in onnxruntime (CPU)
    python benchmarks/bench_stream.py --json --bf16        # + the step under bf16 autocast beside fp32
    python benchmarks/bench_stream.py --json --int8        # + the step with int8 Linear layers beside fp32

For each backbone width (``paper``: recipes/backbones/skeleton_mamba.yaml; ``tiny``:
skeleton_mamba_tiny.yaml) the causal dance network (:class:`StreamDancer`, SMPL-24, random weights)
runs in a fresh subprocess with ``--threads`` torch threads under ``torch.inference_mode``:

- ``step``: one :meth:`StreamDancer.step` per 30 fps frame fed its own previous pose and a music
  feature row; median / p99 / max latency over ``--frames`` frames, and frames per second;
- ``step_sequence_path``: the same step with the frame-wise scans through the modules' sequence path
  (``streaming.step(..., ops=None)``, the path before ``FrameOps``), timed on alternate frames of
  the same run with its own state, and ``sequence_path_over_step`` the ratio of the medians;
- ``compiled`` (``--compile [MODE]``): the step compiled with :mod:`skeleton_mamba.runtime.compiling`
  (inductor, frozen weights, as ``sm stream --compile``): ``compile_seconds``, then compiled and eager steps
  on alternate frames of the same run, each with its own state and both fed the eager step's previous pose:
  median / p99 / max / fps of both, the ratios eager over compiled (median, p99), frames over 33 ms, and the
  largest difference of their outputs (fp32 rounding); ``compiled.alone``: the compiled step by itself, frame
  after frame as ``sm stream --compile`` runs it (no eager step in between to evict its weights from the
  caches); the memory run below then streams compiled;
- ``windowed``: what a windowed model pays per new frame, re-running the same network's forward on
  the last ``--window`` frames (5 s) and keeping the last output; median over ``--window-repeats``;
- ``onnx`` (``--onnx``): the dancer's step graph of ``sm export-onnx`` (the state as explicit inputs and
  outputs) in onnxruntime and the eager step on alternate frames, fed the same poses: median / p99 / max /
  fps of both, the ratio and the largest difference;
- ``bf16`` (``--bf16``): the eager step in fp32 and under bf16 autocast (``sm stream --precision bf16``)
  on alternate frames, each with its own state: median / p99 / fps of both, the ratio and bf16's
  largest difference from fp32;
- ``int8`` (``--int8``): the same with the step's Linear layers dynamically quantized to int8 (``sm stream
  --quantize int8``) in place of bf16;
- ``gemm``: this machine's fp32 and bf16 ``torch.matmul`` rates (GFLOP/s, best of n = 512, 1024, 2048);
- ``features``: the causal music features of one frame (:mod:`tasks.stream.features`, 44.1 kHz in);
- ``memory``: resident set size (VmRSS) after streaming ``--memory-minutes`` minutes of frames as
  fast as possible (synthetic features; at the paper width 10 minutes are 18,000 steps, about as long
  as the music itself; progress on stderr), and the size of the recurrent state;
- ``tail``: what else happened during the timed steps, per frame: Python garbage collections (count,
  total and longest pause, ``gc.callbacks``), minor page faults (fresh memory the allocator took from
  the kernel) and involuntary context switches (the process was preempted: other load on the machine);
- ``--profile N``: the N operators with the most self CPU time over 20 steps (``torch.profiler``).

The machine load (``os.getloadavg``) before and after is printed beside the figures: on a shared
machine the latencies are upper bounds; the ratios measured side by side are the robust part.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import gemm_gflop_per_s, machine_info  # noqa: E402

WIDTHS = {"paper": "skeleton_mamba.yaml", "tiny": "skeleton_mamba_tiny.yaml"}


def rss_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def gemm_rates(threads: int) -> dict:
    """This machine's fp32 and bf16 GEMM rates (``torch.matmul``, GFLOP/s) with ``threads`` threads."""
    import torch

    torch.set_num_threads(threads)
    sizes = (512, 1024, 2048)
    return {"fp32": gemm_gflop_per_s(sizes), "bf16": gemm_gflop_per_s(sizes, dtype=torch.bfloat16)}


def build(width: str):
    import yaml

    from skeleton_mamba.recipes import __file__ as recipes_init
    from skeleton_mamba.tasks.stream.model import StreamDancer
    from skeleton_mamba.tasks.training.backbone_config import backbone_config

    fragment = Path(recipes_init).parent / "backbones" / WIDTHS[width]
    config = backbone_config(yaml.safe_load(fragment.read_text()))
    return StreamDancer(config).eval()


class GcPauses:
    """Count and time the Python garbage collections while active (``gc.callbacks``)."""

    def __init__(self) -> None:
        self.pauses_ms: list[float] = []
        self._start = 0.0

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._start = time.perf_counter()
        else:
            self.pauses_ms.append(1e3 * (time.perf_counter() - self._start))

    def __enter__(self) -> GcPauses:
        gc.callbacks.append(self)
        return self

    def __exit__(self, *exc) -> None:
        gc.callbacks.remove(self)


def profile_table(model, rows: int) -> str:
    """Operators by self CPU time over 20 steps (after 5 warm-up steps), and the matrix products' share."""
    import torch
    from common import operator_profile

    prev, music = torch.zeros(1, 24, 12), torch.randn(1, 34)
    with torch.inference_mode():
        state = model.init_state(1)
        for _ in range(5):
            prev, state = model.step(prev, music, state)

        def steps():
            nonlocal prev, state
            for _ in range(20):
                prev, state = model.step(prev, music, state)

        table, gemm_share = operator_profile(steps, rows)
    return f"{table}\nmatrix products: {100 * gemm_share:.0f} % of the self CPU time"


def compiled_and_eager(model, backbone_step, count: int) -> dict:
    """Alternate frames of the compiled and the eager step, each with its own state, both fed the eager
    step's previous pose (the same inputs): latencies of both, their ratios, and the largest difference."""
    import numpy as np
    import torch

    from skeleton_mamba.tasks.training.frame_timing import latency_summary

    music = torch.randn(1, 34)
    prev = torch.zeros(1, 24, 12)
    state, eager_state = model.init_state(1), model.init_state(1)
    times, eager_times, difference = [], [], 0.0
    for i in range(count + 10):  # 10 warm-up frames
        start = time.perf_counter()
        out, state = model.step(prev, music, state, backbone_step)
        elapsed = 1e3 * (time.perf_counter() - start)
        start = time.perf_counter()
        prev, eager_state = model.step(prev, music, eager_state)
        eager_elapsed = 1e3 * (time.perf_counter() - start)
        difference = max(difference, float((out - prev).abs().max()))
        if i >= 10:
            times.append(elapsed)
            eager_times.append(eager_elapsed)
    times, eager_times = np.asarray(times), np.asarray(eager_times)
    compiled, eager = latency_summary(times), latency_summary(eager_times)
    return {
        **{k: round(v, 3) for k, v in compiled.items()},
        "fps": round(1e3 / float(np.mean(times)), 1),
        "frames_over_33ms": int((times > 33.0).sum()),
        **{f"eager_{k}_same_frames": round(v, 3) for k, v in eager.items()},
        "eager_fps_same_frames": round(1e3 / float(np.mean(eager_times)), 1),
        "eager_frames_over_33ms": int((eager_times > 33.0).sum()),
        "eager_over_compiled_median": round(eager["median_ms"] / compiled["median_ms"], 2),
        "eager_over_compiled_p99": round(eager["p99_ms"] / compiled["p99_ms"], 2),
        "max_abs_difference": float(f"{difference:.3g}"),
        "output_max_abs": round(float(prev.abs().max()), 3),
        "frames": count,
    }


def onnx_and_eager(model, frames: int, threads: int) -> dict:
    """The dancer's step exported to ONNX (``sm export-onnx``'s step graph: music standardisation, the
    backbone's step, the state as inputs and outputs) in onnxruntime on the CPU, and the eager
    :meth:`StreamDancer.step`, on alternate frames of the same run, each with its own state and both fed
    the same previous pose and music: median / p99 / max / fps of both, their ratio and the largest
    difference of their outputs."""
    import tempfile

    import numpy as np
    import onnxruntime
    import torch

    from skeleton_mamba.tasks.stream.onnx_graphs import dancer_specs
    from skeleton_mamba.tasks.training import onnx_export
    from skeleton_mamba.tasks.training.frame_timing import latency_summary

    spec = dancer_specs(model)["step"]  # a size-1 example would fix the batch; runs at 1
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        path = onnx_export.export_onnx(spec, Path(folder) / "step.onnx")
        export_seconds = time.perf_counter() - start
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = threads
        session = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    names = spec.input_names
    states = [t.numpy() for t in onnx_export.zero_states(model.backbone, 1)]
    eager_state = model.init_state(1)
    prev, music = torch.zeros(1, 24, 12), torch.randn(1, 34)
    ort_ms, eager_ms, difference = [], [], 0.0
    for i in range(frames + 10):
        start = time.perf_counter()
        pose, *states = session.run(None, dict(zip(names, [prev.numpy(), music.numpy(), *states])))
        ort_elapsed = 1e3 * (time.perf_counter() - start)
        start = time.perf_counter()
        out, eager_state = model.step(prev, music, eager_state)
        eager_elapsed = 1e3 * (time.perf_counter() - start)
        difference = max(difference, float(np.abs(pose - out.numpy()).max()))
        prev = out  # the eager step's pose feeds both
        if i >= 10:  # warm-up
            ort_ms.append(ort_elapsed)
            eager_ms.append(eager_elapsed)
    ort_ms, eager_ms = np.asarray(ort_ms), np.asarray(eager_ms)
    ort, eager = latency_summary(ort_ms), latency_summary(eager_ms)
    return {
        "export_seconds": round(export_seconds, 1),
        **{k: round(v, 3) for k, v in ort.items()},
        "fps": round(1e3 / float(np.mean(ort_ms)), 1),
        **{f"eager_{k}_same_frames": round(v, 3) for k, v in eager.items()},
        "eager_fps_same_frames": round(1e3 / float(np.mean(eager_ms)), 1),
        "eager_over_onnx_median": round(eager["median_ms"] / ort["median_ms"], 2),
        "eager_over_onnx_p99": round(eager["p99_ms"] / ort["p99_ms"], 2),
        "max_abs_difference": float(f"{difference:.3g}"),
        "frames": frames,
    }


def variant_and_fp32(model, frames: int, name: str, step) -> dict:
    """The eager step in fp32 and ``step`` (``model.step``'s signature: another precision or quantization of
    it) on alternate frames of the same run, each with its own state, both fed the fp32 step's previous
    pose: median / p99 / fps of both, the ratio fp32 over ``name``, and ``name``'s largest difference from
    fp32 (absolute, and relative to the largest fp32 output)."""
    import numpy as np  # lazy: after --help
    import torch  # lazy: after --help

    from skeleton_mamba.tasks.training.frame_timing import latency_summary  # lazy: after --help

    music, prev = torch.randn(1, 34), torch.zeros(1, 24, 12)
    state, other_state = model.init_state(1), model.init_state(1)
    fp32_ms, other_ms, difference, largest = [], [], 0.0, 0.0
    for i in range(frames + 10):
        start = time.perf_counter()
        other, other_state = step(prev, music, other_state)
        other_elapsed = 1e3 * (time.perf_counter() - start)
        start = time.perf_counter()
        prev, state = model.step(prev, music, state)
        fp32_elapsed = 1e3 * (time.perf_counter() - start)
        difference = max(difference, float((other.float() - prev).abs().max()))
        largest = max(largest, float(prev.abs().max()))
        if i >= 10:  # warm-up
            fp32_ms.append(fp32_elapsed)
            other_ms.append(other_elapsed)
    fp32_ms, other_ms = np.asarray(fp32_ms), np.asarray(other_ms)
    fp32, other = latency_summary(fp32_ms), latency_summary(other_ms)
    return {
        **{f"fp32_{k}": round(v, 3) for k, v in fp32.items()},
        "fp32_fps": round(1e3 / float(np.mean(fp32_ms)), 1),
        **{f"{name}_{k}": round(v, 3) for k, v in other.items()},
        f"{name}_fps": round(1e3 / float(np.mean(other_ms)), 1),
        f"fp32_over_{name}_median": round(fp32["median_ms"] / other["median_ms"], 2),
        "max_abs_difference": float(f"{difference:.3g}"),
        "max_relative_difference": float(f"{difference / max(largest, 1e-12):.3g}"),
        "frames": frames,
    }


def bf16_and_fp32(model, frames: int) -> dict:
    """:func:`variant_and_fp32` of the step under bf16 autocast (``sm stream --precision bf16``)."""
    from skeleton_mamba.ssd.precision import inference_precision  # lazy: after --help

    def bf16_step(prev, music, state):
        with inference_precision("bf16"):
            return model.step(prev, music, state)

    return variant_and_fp32(model, frames, "bf16", bf16_step)


def int8_and_fp32(model, frames: int) -> dict:
    """:func:`variant_and_fp32` of the step with every Linear dynamically quantized to int8 (``sm stream
    --quantize int8``)."""
    import copy  # lazy: after --help

    from skeleton_mamba.tasks.stream.stream_cli import quantize_linear_int8  # lazy: after --help

    return variant_and_fp32(model, frames, "int8", quantize_linear_int8(copy.deepcopy(model)).step)


def measure(
    width: str,
    frames: int,
    window: int,
    window_repeats: int,
    minutes: list[float],
    memory_only: bool = False,
    compile_mode: str | None = None,
    onnx: bool = False,
    bf16: bool = False,
    int8: bool = False,
) -> dict:
    """All figures of one width (run in a subprocess); ``compile_mode``: None, or "default" (or a
    ``torch.compile`` mode) to add the compiled step."""
    import numpy as np
    import torch

    from skeleton_mamba.runtime import streaming
    from skeleton_mamba.tasks.stream.features import CausalMusicFeatures
    from skeleton_mamba.tasks.training.frame_timing import latency_summary

    torch.manual_seed(0)
    model = build(width)
    params = sum(p.numel() for p in model.parameters())
    music = torch.randn(1, 34)
    prev = torch.zeros(1, 24, 12)

    backbone_step = None  # the eager step
    result = {"width": width, "parameters": params, "threads": torch.get_num_threads()}
    if compile_mode:  # under inference_mode as the timed steps (inference tensors: one signature)
        from skeleton_mamba.runtime.compiling import compile_step_or_eager

        mode = None if compile_mode == "default" else compile_mode
        print(f"[{width}] compiling the step ({compile_mode})...", file=sys.stderr, flush=True)
        with torch.inference_mode():
            backbone_step, seconds = compile_step_or_eager(model.backbone, mode=mode)
        result["compiled"] = {"mode": compile_mode, "compile_seconds": seconds and round(seconds, 1)}
        if seconds is not None:
            print(f"[{width}] compiled in {seconds:.0f} s; timing", file=sys.stderr, flush=True)
        if seconds is None:
            backbone_step = None
            result["compiled"]["error"] = "compiling failed (the warning on stderr says why): eager only"

    def run(count: int, state) -> list[float]:
        nonlocal prev
        times = []
        for _ in range(count):
            start = time.perf_counter()
            prev, state = model.step(prev, music, state, backbone_step)
            times.append(1e3 * (time.perf_counter() - start))
        return times

    def run_both(count: int, state, reference_state) -> tuple[list[float], list[float]]:
        """Alternate frames: ``model.step`` (FrameOps) and the sequence path, each with its own state."""
        nonlocal prev
        times, reference_times, reference_prev = [], [], prev
        for _ in range(count):
            start = time.perf_counter()
            prev, state = model.step(prev, music, state)
            times.append(1e3 * (time.perf_counter() - start))
            start = time.perf_counter()
            out, reference_state = streaming.step(
                model.backbone, model._inputs(reference_prev, music), reference_state, ops=None
            )
            reference_times.append(1e3 * (time.perf_counter() - start))
            reference_prev = out
        return times, reference_times

    if onnx and not memory_only:
        print(f"[{width}] exporting the step to ONNX; timing", file=sys.stderr, flush=True)
        with torch.no_grad():
            result["onnx"] = onnx_and_eager(model, frames, torch.get_num_threads())
    if bf16 and not memory_only:
        print(f"[{width}] fp32 and bf16 steps on alternate frames", file=sys.stderr, flush=True)
        with torch.inference_mode():
            result["bf16"] = bf16_and_fp32(model, frames)
    if int8 and not memory_only:
        print(f"[{width}] fp32 and int8 steps on alternate frames", file=sys.stderr, flush=True)
        with torch.inference_mode():
            result["int8"] = int8_and_fp32(model, frames)
    with torch.inference_mode():
        if not memory_only and backbone_step is not None:
            result["compiled"].update(compiled_and_eager(model, backbone_step, frames))
            state = model.init_state(1)
            run(10, state)  # warm-up
            usage = resource.getrusage(resource.RUSAGE_SELF)
            alone_ms = np.asarray(run(frames, state))
            after = resource.getrusage(resource.RUSAGE_SELF)
            result["compiled"]["alone"] = {
                **{k: round(v, 3) for k, v in latency_summary(alone_ms).items()},
                "fps": round(1e3 / float(np.mean(alone_ms)), 1),
                "frames_over_33ms": int((alone_ms > 33.0).sum()),
                "involuntary_switches_per_frame": round((after.ru_nivcsw - usage.ru_nivcsw) / frames, 2),
                "frames": frames,
            }
        compiled_step, backbone_step = backbone_step, None  # the eager step for the figures below
        if not memory_only:
            state = model.init_state(1)
            run(10, state)  # warm-up
            usage = resource.getrusage(resource.RUSAGE_SELF)
            with GcPauses() as collections:
                step_ms = np.asarray(run(frames, state))
            after = resource.getrusage(resource.RUSAGE_SELF)
            pauses = np.asarray(collections.pauses_ms)
            summary = latency_summary(step_ms)
            result["step"] = {
                **{k: round(v, 3) for k, v in summary.items()},
                "fps": round(1e3 / float(np.mean(step_ms)), 1),
                "frames": frames,
            }  # fmt: skip
            both = run_both(frames, model.init_state(1), model.init_state(1))
            paired, reference = (np.asarray(t) for t in both)
            result["step_sequence_path"] = {
                **{k: round(v, 3) for k, v in latency_summary(reference).items()},
                "step_median_ms_same_frames": round(float(np.median(paired)), 3),
                "sequence_path_over_step": round(float(np.median(reference) / np.median(paired)), 2),
            }
            result["tail"] = {
                "gc_collections": len(pauses),
                "gc_total_ms": round(float(pauses.sum()), 3),
                "gc_max_ms": round(float(pauses.max()), 3) if len(pauses) else 0.0,
                "minor_faults_per_frame": round((after.ru_minflt - usage.ru_minflt) / frames, 2),
                "involuntary_switches_per_frame": round((after.ru_nivcsw - usage.ru_nivcsw) / frames, 2),
                "frames_over_33ms": int((step_ms > 33.0).sum()),
            }
            history = torch.zeros(1, window, 24, 12)
            music_window = torch.randn(1, window, 34)
            model(history, music_window)
            windowed = []
            for _ in range(window_repeats):
                start = time.perf_counter()
                model(history, music_window)[:, -1]
                windowed.append(1e3 * (time.perf_counter() - start))
            result["windowed"] = {
                "window_frames": window,
                "median_ms_per_new_frame": round(float(np.median(windowed)), 2),
            }
            extractor = CausalMusicFeatures(44100)
            audio = np.random.default_rng(0).standard_normal(44100 * 2).astype(np.float32) * 0.1
            hop = 44100 // 30
            extractor.push(audio[: 4 * hop])
            feature_ms = []
            for s in range(4 * hop, len(audio) - hop, hop):
                start = time.perf_counter()
                extractor.push(audio[s : s + hop])
                feature_ms.append(1e3 * (time.perf_counter() - start))
            result["features"] = {k: round(v, 3) for k, v in latency_summary(np.asarray(feature_ms)).items()}
        memory = {}
        backbone_step = compiled_step  # as `sm stream` runs it
        state = model.init_state(1)
        done, start = 0, time.perf_counter()
        for m in sorted(minutes):
            target = int(round(m * 60 * 30))
            while done < target:  # one minute of frames at a time, with progress on stderr
                chunk = min(target - done, 60 * 30)
                run(chunk, state)
                done += chunk
                elapsed = time.perf_counter() - start
                progress = f"{done / 1800:.1f} min of frames streamed in {elapsed:.0f} s"
                print(f"[{width}] {progress}, RSS {rss_mib():.1f} MiB", file=sys.stderr, flush=True)
            memory[f"rss_mib_after_{m:g}_min"] = round(rss_mib(), 1)
    memory["step"] = "eager" if compiled_step is None else "compiled"
    result["memory"] = {**memory, "state_bytes": state.nbytes, "frames_streamed": done}
    return result


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
    p.add_argument("--memory-only", action="store_true", help="only the resident-memory figures (no timing)")
    p.add_argument(
        "--profile",
        type=int,
        default=0,
        metavar="N",
        help="print the N operators with the most self CPU time over 20 steps and exit",
    )
    p.add_argument(
        "--adaptive-malloc",
        action="store_true",
        help="leave glibc's adaptive malloc thresholds (default: keep_freed_memory, as sm stream)",
    )
    p.add_argument(
        "--compile",
        nargs="?",
        const="default",
        default=None,
        metavar="MODE",
        help="also time the step compiled with torch.compile (skeleton_mamba.runtime.compiling; MODE: a "
        "torch.compile mode, default 'default') side by side with the eager step; memory run compiled",
    )
    p.add_argument(
        "--onnx",
        action="store_true",
        help="also time the dancer's step exported to ONNX in onnxruntime (CPU) beside the eager step",
    )
    p.add_argument(
        "--bf16",
        action="store_true",
        help="also time the eager step under bf16 autocast (--precision bf16) beside the fp32 one",
    )
    p.add_argument(
        "--int8",
        action="store_true",
        help="also time the eager step with its Linear layers quantized to int8 (sm stream --quantize int8)",
    )
    p.add_argument("--width-only", help=argparse.SUPPRESS)
    args = p.parse_args()
    minutes = [float(m) for m in args.memory_minutes.split(",")]
    if args.width_only:
        import torch

        from skeleton_mamba.runtime.allocator import keep_freed_memory

        torch.set_num_threads(args.threads)
        if not args.adaptive_malloc:
            keep_freed_memory()  # as `sm stream` does
        if args.profile:
            print(profile_table(build(args.width_only), args.profile), file=sys.stderr)
            print(json.dumps({"width": args.width_only, "profiled": True}))
            return 0
        figures = measure(
            args.width_only,
            args.frames,
            args.window,
            args.window_repeats,
            minutes,
            args.memory_only,
            args.compile,
            args.onnx,
            args.bf16,
            args.int8,
        )
        print(json.dumps(figures))
        return 0
    results = {
        "machine": machine_info(),
        "omp_wait_policy": args.omp_wait_policy
        if args.omp_wait_policy != "inherit"
        else os.environ.get("OMP_WAIT_POLICY", "default"),
        "load_before": [round(v, 2) for v in os.getloadavg()],
        "gemm": gemm_rates(args.threads),
        "widths": {},
    }
    for width in args.widths.split(","):
        cmd = [sys.executable, __file__, "--width-only", width, "--threads", str(args.threads)]
        cmd += ["--frames", str(args.frames), "--window", str(args.window)]
        cmd += ["--window-repeats", str(args.window_repeats), "--memory-minutes", args.memory_minutes]
        cmd += ["--memory-only"] * args.memory_only + ["--profile", str(args.profile)]
        cmd += ["--adaptive-malloc"] * args.adaptive_malloc
        cmd += ["--compile", args.compile] if args.compile else []
        cmd += ["--onnx"] * args.onnx + ["--bf16"] * args.bf16 + ["--int8"] * args.int8
        env = dict(os.environ, OMP_NUM_THREADS=str(args.threads))
        if args.omp_wait_policy != "inherit":
            env["OMP_WAIT_POLICY"] = args.omp_wait_policy.upper()
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, text=True, env=env)  # progress: stderr
        if proc.returncode:
            return proc.returncode
        results["widths"][width] = json.loads(proc.stdout.strip().splitlines()[-1])
    results["load_after"] = [round(v, 2) for v in os.getloadavg()]
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print(results["machine"])
    print(f"load (1/5/15 min) before {results['load_before']}, after {results['load_after']}")
    g = results["gemm"]
    fp32, bf16 = g["fp32"], g["bf16"]
    print(f"GEMM ({fp32['threads']} threads): fp32 {fp32['gflop_per_s']:.0f} GFLOP/s (n = {fp32['size']}),"
          f" bf16 {bf16['gflop_per_s']:.0f} GFLOP/s (n = {bf16['size']})")  # fmt: skip
    for width, r in results["widths"].items():
        if "memory" not in r:
            continue
        line = f"{width:5s} {r['parameters'] / 1e6:6.2f} M params, {r['threads']} threads:"
        if "step" in r:
            s, w = r["step"], r["windowed"]
            line += (
                f" step median {s['median_ms']:.2f} ms, p99 {s['p99_ms']:.2f} ms, {s['fps']:.0f} fps"
                f" | windowed ({w['window_frames']} frames) {w['median_ms_per_new_frame']:.1f} ms/frame"
                f" | features {r['features']['median_ms']:.2f} ms | {r['tail']} | sequence path"
                f" {r['step_sequence_path']['sequence_path_over_step']}x the step |"
            )
        print(f"{line} {r['memory']}")
        c = r.get("compiled")
        if c and "median_ms" in c:
            print(
                f"      compiled ({c['mode']}, {c['compile_seconds']:.0f} s to compile):"
                f" median {c['median_ms']:.2f} ms, p99 {c['p99_ms']:.2f} ms, {c['fps']:.0f} fps"
                f" | eager on the alternate frames: median {c['eager_median_ms_same_frames']:.2f} ms,"
                f" p99 {c['eager_p99_ms_same_frames']:.2f} ms"
                f" ({c['eager_over_compiled_median']}x, p99 {c['eager_over_compiled_p99']}x)"
                f" | max difference {c['max_abs_difference']:.2g}"
            )
        elif c:
            print(f"      compiled: {c.get('error')}")
        o = r.get("onnx")
        if o:
            print(
                f"      onnxruntime step: median {o['median_ms']:.2f} ms, p99 {o['p99_ms']:.2f} ms,"
                f" {o['fps']:.0f} fps | eager on the alternate frames: median"
                f" {o['eager_median_ms_same_frames']:.2f} ms, p99 {o['eager_p99_ms_same_frames']:.2f} ms"
                f" ({o['eager_over_onnx_median']}x) | max difference {o['max_abs_difference']:.2g}"
            )
        b = r.get("bf16")
        if b:
            print(
                f"      fp32 vs bf16 step (alternate frames): median {b['fp32_median_ms']:.2f} vs"
                f" {b['bf16_median_ms']:.2f} ms, p99 {b['fp32_p99_ms']:.2f} vs {b['bf16_p99_ms']:.2f} ms,"
                f" {b['fp32_fps']:.0f} vs {b['bf16_fps']:.0f} fps ({b['fp32_over_bf16_median']}x) | bf16"
                f" max difference {b['max_abs_difference']:.2g} ({b['max_relative_difference']:.2g} relative)"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
