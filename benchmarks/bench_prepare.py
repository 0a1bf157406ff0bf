"""Throughput of ``sm prepare ntu60`` (raw .skeleton files per second), 2 processes versus 1.

Generates a folder of realistic raw files (default 200 files of 90-110 frames, 1 or 2 bodies, CRLF, the
official 12-values-per-joint layout, about 250-500 kB each) and times :func:`prepare_ntu` end to end:
parsing, body selection, split assignment and the atomic pickle write.

    python benchmarks/bench_prepare.py [--files 200] [--repeats 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

from skeleton_mamba.tasks.recognition.prepare import prepare_ntu  # noqa: E402


def write_raw_file(path: Path, num_frames: int, num_bodies: int, rng: np.random.Generator) -> None:
    """One raw file in the official text layout with smoothly moving bodies."""
    base = rng.normal(0.0, 0.3, (num_bodies, 25, 3)) + [0.0, 0.0, 3.0]
    drift = np.cumsum(rng.normal(0.0, 0.01, (num_bodies, num_frames, 25, 3)), axis=1)
    lines = [str(num_frames)]
    for t in range(num_frames):
        lines.append(str(num_bodies))
        for b in range(num_bodies):
            lines.append(f"{72057594037931101 + b} 0 1 1 1 1 0 0.02764709 0.05745083 2")
            lines.append("25")
            for x, y, z in base[b] + drift[b, t]:
                lines.append(f"{x:.7g} {y:.7g} {z:.7g} 277.419 191.8218 1036.233 519.1677 "
                             "-0.2059419 0.05349901 0.9692109 -0.1239193 2")  # fmt: skip
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode("ascii"))


def make_folder(root: Path, num_files: int, seed: int = 0) -> int:
    """Write ``num_files`` NTU60 samples under ``root``; returns the total size in bytes."""
    rng = np.random.default_rng(seed)
    for i in range(num_files):
        name = f"S{1 + i % 17:03d}C{1 + i % 3:03d}P{1 + i % 40:03d}R{1 + i % 2:03d}A{1 + i % 60:03d}"
        write_raw_file(root / f"{name}.skeleton", int(rng.integers(90, 111)), 1 + i % 2, rng)
    return sum(p.stat().st_size for p in root.iterdir())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--files", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(tmp) / "raw"
        raw.mkdir()
        size = make_folder(raw, args.files)
        results = {}
        for workers in (2, 1):
            times = []
            for r in range(args.repeats):
                start = time.perf_counter()
                summary = prepare_ntu("ntu60", raw, Path(tmp) / f"out_{workers}_{r}.pkl", workers=workers)
                times.append(time.perf_counter() - start)
            assert summary["written"] + summary["missing_excluded"] == args.files, summary
            median = statistics.median(times)
            rate = round(args.files / median, 1)
            results[f"workers_{workers}"] = {"median_s": round(median, 3), "files_per_s": rate}
    report = {
        "benchmark": "sm prepare ntu60 throughput",
        "machine": machine_info(),
        "files": args.files,
        "mean_file_kb": round(size / args.files / 1024, 1),
        "repeats": args.repeats,
        **results,
        "speedup_2_vs_1": round(results["workers_1"]["median_s"] / results["workers_2"]["median_s"], 2),
    }
    if args.json:
        print(json.dumps(report))
    else:
        for key, value in report.items():
            print(f"{key}: {value}")


if __name__ == "__main__":
    main()
