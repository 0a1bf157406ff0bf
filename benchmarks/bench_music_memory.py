"""Peak memory of the music feature on tracks of 1, 20 and 55 minutes: analysed in windows (long tracks,
:mod:`skeleton_mamba.tasks.motion.music.music_windows`) against the whole-track analysis.

    python benchmarks/bench_music_memory.py [--json] [--minutes 1 20 55] [--fps 30] [--as windowed whole]

Each analysis runs in a fresh process (``sm``'s own feature path, the cache off) on a synthetic drum track
written as 16-bit WAV at 22050 Hz (a 60 s pattern repeated); the peak resident memory of that process and
its wall time are reported. "whole" analyses the whole track at once (the path of tracks up to
``LONG_TRACK_S``), "windowed" the long-track path.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import soundfile as sf

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

CHILD = """
import resource, sys
from skeleton_mamba.tasks.motion.music import music_windows
from skeleton_mamba.tasks.motion.music.features import extract_music_features
path, fps, how = sys.argv[1], int(sys.argv[2]), sys.argv[3]
music_windows.LONG_TRACK_S = 0.0 if how == "windowed" else float("inf")
analysis = extract_music_features(path, fps=fps, use_cache=False)
print(len(analysis.features), analysis.tempo_bpm, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


HOWS = ("windowed", "whole")


def write_track(path: Path, minutes: float, sr: int = 22050) -> Path:
    """A ``minutes``-long drum track: a 60 s synthetic pattern written block by block."""
    from skeleton_mamba.tasks.motion.synthetic import synthesize_music

    block = synthesize_music(120.0, 60.0, sr=sr, seed=0).audio.astype(np.float32)
    total = int(minutes * 60 * sr)
    with sf.SoundFile(path, "w", sr, 1, "PCM_16") as f:
        written = 0
        while written < total:
            piece = block[: total - written]
            f.write(piece)
            written += len(piece)
    return path


def measure(path: Path, fps: int, how: str) -> dict:
    """One analysis in a fresh process: its wall seconds, frames, tempo and peak resident memory."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CHILD, str(path), str(fps), how], capture_output=True,
                          text=True, check=False)  # fmt: skip
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        return {"error": (done.stderr.strip().splitlines() or [str(done.returncode)])[-1]}
    frames, tempo, peak_kb = done.stdout.split()[-3:]
    return {"seconds": round(seconds, 1), "frames": int(frames), "tempo_bpm": float(tempo),
            "peak_mb": round(int(peak_kb) / 1024)}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--minutes", type=float, nargs="+", default=[1.0, 20.0, 55.0])
    p.add_argument("--fps", type=int, default=30)
    p.add_argument(
        "--as", dest="hows", nargs="+", default=["windowed", "whole"], choices=("windowed", "whole")
    )
    args = p.parse_args(argv)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for minutes in sorted(args.minutes):
            path = write_track(Path(tmp) / f"track_{minutes:g}min.wav", minutes)
            for how in args.hows:
                row = {"minutes": minutes, "as": how, **measure(path, args.fps, how)}
                results.append(row)
                if not args.json:
                    print(json.dumps(row))
    result = {"machine": machine_info(), "fps": args.fps, "runs": results}
    if args.json:
        print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
