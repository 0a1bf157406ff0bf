"""The browser dancer's per-frame time: onnxruntime-web (wasm) in headless Chromium beside ``sm stream``.

    python benchmarks/bench_web.py --json                       # tiny (demo) and paper widths
    python benchmarks/bench_web.py --json --widths tiny --frames 300

For each backbone width (``tiny``: the stream demo's skeleton_mamba_tiny.yaml; ``paper``:
skeleton_mamba.yaml) a :class:`StreamDancer` with random weights and the demo's 8-stage low-pass is
written as ``sm export-web``'s page (:func:`~skeleton_mamba.tasks.stream.web_export.write_web_page`), then
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
    from tests.helpers.browser_page import Page

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
    import torch

    from skeleton_mamba.tasks.stream.features import HOP, SR
    from skeleton_mamba.tasks.stream.live import LiveDancer

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


def bench_width(width: str, frames: int, compile: bool, ort_tarball: str | None) -> dict:
    import torch

    from skeleton_mamba.tasks.stream.model import StreamDancer
    from skeleton_mamba.tasks.stream.ort_web import read_ort_web
    from skeleton_mamba.tasks.stream.web_export import write_web_page
    from skeleton_mamba.tasks.training.onnx_export import backbone_from_yaml

    torch.manual_seed(0)
    config = backbone_from_yaml(WIDTHS[width], {}).config
    dancer = StreamDancer(config, smoothing_stages=8).eval()
    params = sum(p.numel() for p in dancer.parameters())
    result: dict = {"params": params}
    with tempfile.TemporaryDirectory() as tmp:
        site = Path(tmp) / "site"
        site.mkdir()
        start = time.perf_counter()
        page, diff = write_web_page(dancer, site, read_ort_web(ort_tarball), f"bench {width}")
        result["export_seconds"] = round(time.perf_counter() - start, 1)
        result["page_mb"] = round(page.stat().st_size / 1e6, 1)
        result["onnxruntime_vs_eager_max_abs"] = float(f"{diff:.3g}")
        web = {"file_1_thread": browser_times(page.as_uri(), frames, Path(tmp) / "p0")}
        handler = functools.partial(IsolatedHandler, directory=str(site))
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        try:
            for n in (1, 2):
                url = f"http://127.0.0.1:{server.server_port}/index.html?threads={n}"
                key = f"served_{n}_thread{'s' if n > 1 else ''}"
                web[key] = browser_times(url, frames, Path(tmp) / f"p{n}")
        finally:
            server.shutdown()
        result["web"] = web
    python = {}
    for threads in (1, 2):
        python[f"eager_{threads}"] = python_times(dancer, frames, threads, False)
        if compile:
            python[f"compiled_{threads}"] = python_times(dancer, frames, threads, True)
    result["sm_stream"] = python
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--widths", default="tiny,paper", help="comma-separated: tiny, paper")
    parser.add_argument("--frames", type=int, default=300, help="timed frames per run")
    parser.add_argument("--no-compile", action="store_true", help="skip sm stream --compile")
    parser.add_argument("--ort-web", default=None, help="onnxruntime-web's npm tarball (default: the cache)")
    args = parser.parse_args()
    load_before = os.getloadavg()
    results = {
        "machine": machine_info(),
        "load_before": [round(x, 2) for x in load_before],
        "frames": args.frames,
        "widths": {},
    }
    for width in args.widths.split(","):
        print(f"bench_web: {width} ...", file=sys.stderr, flush=True)
        results["widths"][width] = bench_width(width, args.frames, not args.no_compile, args.ort_web)
    results["load_after"] = [round(x, 2) for x in os.getloadavg()]
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        for width, r in results["widths"].items():
            runs = {**{f"web {k}": v for k, v in r["web"].items()}, **{f"sm stream {k}": v for k, v in
                    r["sm_stream"].items()}}  # fmt: skip
            for name, v in runs.items():
                print(f"{width:6s} {name:28s} median {v['median_ms']:8.2f} ms  p99 {v['p99_ms']:8.2f}  "
                      f"{v['fps']:8.1f} fps  threads {v['threads']}")  # fmt: skip


if __name__ == "__main__":
    main()
