"""Start-up time of ``sm``: how long a fresh process takes for ``--help``, a refused argument and a cached
music analysis.

Each command line runs ``--repeats`` times (default 5) as a fresh process of the installed ``sm`` console
script, timed from start to exit (wall clock); the median is compared with the goal:

- ``sm --help``: at most 0.5 s;
- ``sm CMD --help`` for every command (and ``sm stream --task recognition --help``): at most 1.5 s, except
  ``fit|validate|test|predict``, whose help is LightningCLI's (it imports Lightning and every task's
  classes to list them), reported with no goal;
- ``sm dance --ckpt X --music missing.wav``: the refusal of a missing input, which comes before torch or the
  checkpoint loads (at most 1.5 s);
- ``sm analyze-music TRACK`` on a track whose features are cached (one untimed run fills a fresh cache
  first): at most 3 s. TRACK is ``--track``, else the first track of ``../shared/data/music`` (skipped,
  with the reason, when absent);
- for reference, no goal: ``python -c "import torch"`` and ``python -c "import lightning.pytorch"``, the floor
  of any command that needs them (LightningCLI's help among them).

The goals hold for a quiet 2-core machine; the load average before and after is recorded, as a busy
machine (other jobs on the cores) stretches every figure.

    python benchmarks/bench_startup.py --json
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

from skeleton_mamba.tasks.training.cli import LIGHTNING_SUBCOMMANDS, available_commands  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
MUSIC = REPO.parent / "shared" / "data" / "music"
HELP_S, COMMAND_HELP_S, ANALYZE_CACHED_S = 0.5, 1.5, 3.0


def sm_executable() -> str:
    """The ``sm`` console script installed beside this interpreter."""
    path = Path(sys.executable).with_name("sm")
    if not path.exists():
        raise SystemExit(f"bench_startup: no sm console script at {path} (pip install -e .)")
    return str(path)


def time_process(argv: list[str], repeats: int, cwd: Path) -> dict:
    """Wall seconds of ``repeats`` fresh runs of ``argv``: median, min, max, and the exit status."""
    seconds, codes = [], set()
    for _ in range(repeats):
        start = time.perf_counter()
        done = subprocess.run(argv, cwd=cwd, capture_output=True, text=True)
        seconds.append(time.perf_counter() - start)
        codes.add(done.returncode)
    return {
        "median_s": round(statistics.median(seconds), 3),
        "min_s": round(min(seconds), 3),
        "max_s": round(max(seconds), 3),
        "exit": sorted(codes),
    }


def command_lines(sm: str, track: Path | None, cache: Path) -> list[tuple[str, list[str], float | None]]:
    """(name, argv, goal in seconds or None) of every command line timed."""
    lines: list[tuple[str, list[str], float | None]] = [("sm --help", [sm, "--help"], HELP_S)]
    for name in available_commands():
        goal = None if name in LIGHTNING_SUBCOMMANDS else COMMAND_HELP_S
        lines.append((f"sm {name} --help", [sm, name, "--help"], goal))
    lines.append(
        (
            "sm stream --task recognition --help",
            [sm, "stream", "--task", "recognition", "--help"],
            COMMAND_HELP_S,
        )
    )
    missing = ["--ckpt", "nosuch.ckpt", "--music", "missing.wav", "--out", "dance_out"]
    lines.append(("sm dance --music missing.wav (refused)", [sm, "dance", *missing], COMMAND_HELP_S))
    if track is not None:
        analyze = [sm, "analyze-music", str(track), "--cache-dir", str(cache)]
        lines.append(("sm analyze-music (cached track)", analyze, ANALYZE_CACHED_S))
    for module in ("torch", "lightning.pytorch"):  # the floor of what imports them (no goal)
        lines.append((f"python -c 'import {module}'", [sys.executable, "-c", f"import {module}"], None))
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5, help="fresh processes per command line")
    ap.add_argument(
        "--track", type=Path, default=None, help="audio file for analyze-music (default: see above)"
    )
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args(argv)
    sm = sm_executable()
    track, skipped = args.track, None
    if track is None:
        tracks = sorted(p for p in MUSIC.glob("*") if p.suffix in (".opus", ".wav", ".mp3", ".flac", ".ogg"))
        track = tracks[0] if tracks else None
        skipped = None if tracks else f"no music in {MUSIC} (pass --track FILE)"
    load_before = os.getloadavg()
    rows = {}
    with tempfile.TemporaryDirectory(prefix="bench_startup_") as tmp:
        cache = Path(tmp) / "cache"
        if track is not None:  # fills the cache: the timed runs read the cached features
            subprocess.run([sm, "analyze-music", str(track), "--cache-dir", str(cache)], check=True,
                           capture_output=True)  # fmt: skip
        for name, command, goal in command_lines(sm, track, cache):
            row = time_process(command, args.repeats, Path(tmp))
            row["goal_s"] = goal
            row["meets_goal"] = None if goal is None else row["median_s"] <= goal
            rows[name] = row
            if not args.json:
                verdict = (
                    "" if goal is None else ("  ok" if row["meets_goal"] else f"  over the {goal} s goal")
                )
                print(f"{name:<42} median {row['median_s']:.3f} s (min {row['min_s']:.3f}){verdict}")
    result = {
        "machine": machine_info(),
        "date": datetime.date.today().isoformat(),
        "python": sys.version.split()[0],
        "load_average_before": [round(v, 2) for v in load_before],
        "load_average_after": [round(v, 2) for v in os.getloadavg()],
        "repeats": args.repeats,
        "analyze_music_skipped": skipped,
        "rows": rows,
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"load average before {result['load_average_before']}, after {result['load_average_after']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
