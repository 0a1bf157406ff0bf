"""The browser dancer's per-frame time: onnxruntime-web (wasm) in headless Chromium beside ``sm stream``.

    python benchmarks/bench_web.py --json                       # tiny (demo) and paper widths
    python benchmarks/bench_web.py --json --widths tiny --frames 300

For each backbone width (``tiny``: the stream demo's skeleton_mamba_tiny.yaml; ``paper``:
skeleton_mamba.yaml) a :class:`StreamDancer` with random weights and the demo's 8-stage low-pass is
written as ``sm export-web``'s page (:func:`~skeleton_mamba.tasks.stream.web_export.export_web_graph`,
:func:`~skeleton_mamba.tasks.stream.web_export.write_page`), then
timed, one frame = one hop of 512 samples (the music features, the step and the joints):

- ``web``: ``window.smDance.bench(frames)`` in headless Chromium (the system's, over CDP as the tests drive
  it): the wall time of each ``session.run`` of the web graph on silence, after 10 warm-up frames;
  ``file_1_thread`` from disk (no cross-origin isolation: one thread), ``served_1_thread`` /
  ``served_2_threads`` from a local server sending ``Cross-Origin-Opener-Policy: same-origin`` and
  ``Cross-Origin-Embedder-Policy: require-corp`` with ``?threads=N``; each records the threads the page
  reports using;
- ``sm_stream``: what ``sm stream`` does per frame (``LiveDancer.push`` of one hop at 15360 Hz: the Python
  features and ``StreamDancer.step``) with 1 and 2 torch threads, eager and compiled (``--compile``);
  ``--no-compile`` skips the compiled runs (a minute or more of compiling at the paper width).

Median / p90 / p99 ms and frames per second (1000 / median) for each. Run it under ``cpu-slot -2`` on a
shared machine, and read the load average printed beside the figures.

``--quantize none,int8,int4`` writes the page at each precision from the one float32 export (``sm export-web
--quantize``, :mod:`~skeleton_mamba.tasks.stream.web_quantize`), times each in Chromium, and compares each
quantized graph's joints with the float32 graph's in onnxruntime over one music track (the first sample
track of ``../shared/data/music``, else a synthetic one): whole, each graph fed its own poses, and one step
at a time from the float32 graph's state. ``--widths ckpt:PATH`` measures a trained dancer (without the
beat phase) instead of a random width; ``--out FILE`` writes the JSON, ``--table --out FILE`` prints the
README table from it::

    python benchmarks/bench_web.py --widths paper --frames 100 --no-compile --quantize none,int8,int4 \
        --out benchmarks/bench_web_quantize.json
    python benchmarks/bench_web.py --table --out benchmarks/bench_web_quantize.json
"""

from __future__ import annotations

import argparse
import functools
import http.server
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.helpers

from common import machine_info  # noqa: E402

WIDTHS = {"tiny": "skeleton_mamba_tiny", "paper": "skeleton_mamba"}
READY = "!!(window.smDance && window.smDance.ready)"


def summary(ms) -> dict:
    ms = np.asarray(ms, dtype=float)
    median = float(np.median(ms))
    return {"median_ms": round(median, 3), "p90_ms": round(float(np.percentile(ms, 90)), 3),
            "p99_ms": round(float(np.percentile(ms, 99)), 3), "fps": round(1e3 / median, 1)}  # fmt: skip


class IsolatedHandler(http.server.SimpleHTTPRequestHandler):
    """A static server whose pages are cross-origin isolated (SharedArrayBuffer: wasm threads)."""

    def end_headers(self) -> None:
        self.send_header("Cross-Origin-Opener-Policy", "same-origin")
        self.send_header("Cross-Origin-Embedder-Policy", "require-corp")
        super().end_headers()

    def log_message(self, *args) -> None:
        pass


def browser_times(url: str, frames: int, profile: Path) -> dict:
    from tests.helpers.browser_page import Page  # lazy: torch and the package load after --help

    page = Page(url, profile)
    try:
        page.wait_for(f"{READY} || !!window.smDance?.error", 900, "the page's start")
        if page.js("window.smDance.error"):
            return {"error": page.js("window.smDance.error")}
        ms = page.js(f"window.smDance.bench({frames})")
        threads = page.js("window.smDance.threads")
        assert not page.errors, page.errors
    finally:
        page.close()
    return {**summary(ms), "threads": threads}


def python_times(dancer, frames: int, threads: int, compile: bool) -> dict:
    import torch  # lazy: torch and the package load after --help

    from skeleton_mamba.tasks.stream.features import HOP, SR  # lazy: torch and the package load after --help
    from skeleton_mamba.tasks.stream.live import LiveDancer  # lazy: torch and the package load after --help

    torch.set_num_threads(threads)
    audio = (0.1 * np.random.default_rng(0).standard_normal(HOP * (frames + 10))).astype(np.float32)
    with torch.inference_mode():
        start = time.perf_counter()
        live = LiveDancer(dancer, SR, compile=compile)
        setup = time.perf_counter() - start
        ms = []
        for t in range(frames + 10):
            start = time.perf_counter()
            live.push(audio[t * HOP : (t + 1) * HOP])
            if t >= 10:
                ms.append(1e3 * (time.perf_counter() - start))
    return {**summary(ms), "threads": threads, **({"compile_seconds": round(setup, 1)} if compile else {})}


def error_track(seconds: float | None):
    """The audio the quantized graphs are compared on: the first sample track of ``../shared/data/music``
    (mono at SR, its first ``seconds`` or whole), else a synthetic drum track of ``seconds`` (30 s)."""
    from skeleton_mamba.tasks.motion.music.features import load_audio  # lazy: after --help
    from skeleton_mamba.tasks.motion.synthetic import synthesize_music  # lazy: after --help
    from skeleton_mamba.tasks.stream.features import SR  # lazy: torch and the package load after --help
    from tests.helpers.repo import SHARED_DATA  # lazy: torch and the package load after --help

    tracks = sorted((SHARED_DATA / "music").glob("*.opus")) if (SHARED_DATA / "music").is_dir() else []
    if tracks:
        audio = load_audio(tracks[0], SR)
        return tracks[0].name, audio if seconds is None else audio[: int(seconds * SR)]
    return "synthetic drums (120 bpm)", synthesize_music(120.0, seconds or 30.0, sr=SR, seed=0).audio


def joints_vs_fp32(dancer, fp32: Path, quantized: Path, track: tuple[str, np.ndarray]) -> dict:
    """The quantized graph's joints against the float32 graph's (onnxruntime's Python CPU provider) over
    ``track``: each run whole with its own poses fed back, and each frame stepped from the float32 graph's
    state (one step: the quantization's own error). Per-joint distances in mm, mean and max."""
    from skeleton_mamba.tasks.stream.web_graph import run_web_graph  # lazy: after --help

    name, audio = track
    reference = run_web_graph(str(fp32), dancer, audio, beside=str(quantized))
    ours = run_web_graph(str(quantized), dancer, audio)["joints"]

    def mm(a, b) -> dict:
        d = 1e3 * np.linalg.norm(a - b, axis=-1)
        return {"mean_mm": round(float(d.mean()), 3), "max_mm": round(float(d.max()), 3)}

    return {"track": name, "frames": len(ours), "whole_track": mm(ours, reference["joints"]),
            "one_step": mm(reference["beside_joints"], reference["joints"])}  # fmt: skip


def web_times(site: Path, page: Path, frames: int, profiles: Path) -> dict:
    """The page's per-frame times from disk (1 thread) and served cross-origin isolated (1 and 2 threads)."""
    web = {"file_1_thread": browser_times(page.as_uri(), frames, profiles / "p0")}
    handler = functools.partial(IsolatedHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        for n in (1, 2):
            url = f"http://127.0.0.1:{server.server_port}/{page.name}?threads={n}"
            key = f"served_{n}_thread{'s' if n > 1 else ''}"
            web[key] = browser_times(url, frames, profiles / f"p{n}")
    finally:
        server.shutdown()
    return web


def bench_width(
    width: str, frames: int, compile: bool, ort_tarball: str | None, quantize: list[str], track
) -> dict:  # fmt: skip
    """One dancer (a width of random weights, or ``ckpt:PATH``): its page at each precision, timed in
    Chromium, each quantized graph's joints against the float32 graph's, and ``sm stream``'s step."""
    import torch  # lazy: torch and the package load after --help

    from skeleton_mamba.tasks.stream.model import StreamDancer  # lazy: after --help
    from skeleton_mamba.tasks.stream.module import StreamDanceModule  # lazy: after --help
    from skeleton_mamba.tasks.stream.ort_web import read_ort_web  # lazy: after --help
    from skeleton_mamba.tasks.stream.web_export import export_web_graph, write_page  # lazy: after --help
    from skeleton_mamba.tasks.stream.web_graph import check_web_dancer  # lazy: after --help
    from skeleton_mamba.tasks.stream.web_quantize import PRECISIONS, quantize_web_graph  # lazy: after --help
    from skeleton_mamba.tasks.training.onnx_export import backbone_from_yaml  # lazy: after --help
    from skeleton_mamba.tasks.training.pretrained import load_module_from  # lazy: after --help

    torch.manual_seed(0)
    if width.startswith("ckpt:"):
        dancer = load_module_from(StreamDanceModule, width[5:]).model.eval()
        check_web_dancer(dancer, width)
    else:
        config = backbone_from_yaml(WIDTHS[width], {}).config
        dancer = StreamDancer(config, smoothing_stages=8).eval()
    params = sum(p.numel() for p in dancer.parameters())
    result: dict = {"params": params, "precisions": {}}
    ort = read_ort_web(ort_tarball)
    with tempfile.TemporaryDirectory() as tmp:
        fp32 = Path(tmp) / "dancer.onnx"
        start = time.perf_counter()
        shapes, diff = export_web_graph(dancer, fp32)
        result["export_seconds"] = round(time.perf_counter() - start, 1)
        result["onnxruntime_vs_eager_max_abs"] = float(f"{diff:.3g}")
        for q in quantize:
            entry: dict = {"precision": PRECISIONS[q]}
            graph = fp32
            if q != "none":
                start = time.perf_counter()
                graph = quantize_web_graph(fp32, Path(tmp) / f"dancer.{q}.onnx", q)
                entry["quantize_seconds"] = round(time.perf_counter() - start, 1)
            entry["graph_mb"] = round(graph.stat().st_size / 1e6, 1)
            site = Path(tmp) / f"site_{q}"
            site.mkdir()
            page = write_page(graph, shapes, site, ort, f"bench {width} {q}", quantize=q)
            entry["page_mb"] = round(page.stat().st_size / 1e6, 1)
            print(f"bench_web: {width} {q}: the page in Chromium ...", file=sys.stderr, flush=True)
            entry["web"] = web_times(site, page, frames, Path(tmp) / f"profiles_{q}")
            if q != "none":
                print(f"bench_web: {width} {q}: joints against fp32 ...", file=sys.stderr, flush=True)
                entry["joints_vs_fp32"] = joints_vs_fp32(dancer, fp32, graph, track)
            result["precisions"][q] = entry
    python = {}
    for threads in (1, 2):
        python[f"eager_{threads}"] = python_times(dancer, frames, threads, False)
        if compile:
            python[f"compiled_{threads}"] = python_times(dancer, frames, threads, True)
    result["sm_stream"] = python
    return result


def fps(run: dict) -> str:
    return (
        f"{run['median_ms']:.1f} ({run['p99_ms']:.1f}): {run['fps']:.1f} fps"
        if "fps" in run
        else run["error"]
    )


def table(results: dict) -> str:
    """The markdown table of ``benchmarks/README.md`` from a JSON report (``--table``)."""
    lines = [
        "| dancer (params) | weights | graph | page | web, disk, 1 thread | web, served, 2 threads "
        "| joints vs fp32, one step: mean / max | whole track: mean / max |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for width, r in results["widths"].items():
        name = f"trained {'/'.join(Path(width[5:]).parts[-4:])}" if width.startswith("ckpt:") else width
        for e in r["precisions"].values():
            err = e.get("joints_vs_fp32")
            one = f"{err['one_step']['mean_mm']:.2f} / {err['one_step']['max_mm']:.2f} mm" if err else "-"
            whole = (
                f"{err['whole_track']['mean_mm']:.2f} / {err['whole_track']['max_mm']:.2f} mm" if err else "-"
            )
            lines.append(
                f"| {name} ({r['params'] / 1e6:.2f} M) | {e['precision']} | {e['graph_mb']} MB "
                f"| {e['page_mb']} MB | {fps(e['web']['file_1_thread'])} "
                f"| {fps(e['web']['served_2_threads'])} | {one} | {whole} |"
            )
    compared = [e["joints_vs_fp32"] for r in results["widths"].values() for e in r["precisions"].values()
                if "joints_vs_fp32" in e]  # fmt: skip
    tracks = {f"{c['track']} ({c['frames']} frames)" for c in compared}
    lines += [
        "",
        f"{results['machine']}; load average {results['load_before'][0]} before, {results['load_after'][0]} "
        f"after; {results['frames']} timed frames per page; joints compared over "
        f"{', '.join(sorted(tracks))}.",
    ]
    return "\n".join(lines)


def main() -> None:
    from skeleton_mamba.tasks.stream.export_web_args import QUANTIZE_CHOICES  # lazy: after --help

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--widths", default="tiny,paper", help="comma-separated: tiny, paper, ckpt:PATH")
    parser.add_argument("--frames", type=int, default=300, help="timed frames per run")
    parser.add_argument("--no-compile", action="store_true", help="skip sm stream --compile")
    parser.add_argument("--ort-web", default=None, help="onnxruntime-web's npm tarball (default: the cache)")
    parser.add_argument(
        "--quantize",
        default="none",
        help=f"comma-separated, each page of a run: {', '.join(QUANTIZE_CHOICES)}",
    )
    parser.add_argument(
        "--track-seconds", type=float, default=None, help="of the joints' track (default: whole)"
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="the JSON file --json writes and --table reads"
    )
    parser.add_argument("--table", action="store_true", help="print the README table of the --out JSON")
    args = parser.parse_args()
    if args.table:
        if args.out is None:
            parser.error("--table reads --out FILE")
        print(table(json.loads(args.out.read_text())))
        return
    quantize = args.quantize.split(",")
    if any(q not in QUANTIZE_CHOICES for q in quantize):
        parser.error(f"--quantize: each of {', '.join(QUANTIZE_CHOICES)}, not {args.quantize}")
    if any(q != "none" for q in quantize) and "none" not in quantize:
        quantize = ["none", *quantize]  # the quantized pages beside the float32 one
    track = error_track(args.track_seconds) if any(q != "none" for q in quantize) else None
    load_before = os.getloadavg()
    results = {
        "machine": machine_info(),
        "load_before": [round(x, 2) for x in load_before],
        "frames": args.frames,
        "quantize": quantize,
        "widths": {},
    }
    for width in args.widths.split(","):
        print(f"bench_web: {width} ...", file=sys.stderr, flush=True)
        compile = not args.no_compile
        results["widths"][width] = bench_width(width, args.frames, compile, args.ort_web, quantize, track)
    results["load_after"] = [round(x, 2) for x in os.getloadavg()]
    if args.out is not None:
        args.out.write_text(json.dumps(results, indent=2) + "\n")
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        for width, r in results["widths"].items():
            runs = {**{f"web {q} {k}": v for q, e in r["precisions"].items() for k, v in e["web"].items()},
                    **{f"sm stream {k}": v for k, v in r["sm_stream"].items()}}  # fmt: skip
            for name, v in runs.items():
                print(f"{width:6s} {name:34s} {fps(v)}  threads {v.get('threads')}")


if __name__ == "__main__":
    main()
