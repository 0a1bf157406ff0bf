"""``sm analyze-music FILE``: tempo, beat times and the 35-d music features of one audio file.

Examples::

    sm analyze-music song.opus                    # tempo and beat times at 60 fps
    sm analyze-music song.wav --fps 30 --out f.npy  # EDGE's 30 fps features saved as (T, 35) .npy
    sm analyze-music song.mp3 --json              # one JSON object on stdout
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sm analyze-music",
        description="Print the tempo (BPM) and beat times of an audio file and optionally save its "
        "35-d FACT/EDGE librosa features (envelope, 20 MFCC, 12 chroma, onset peaks, beats).",
    )
    p.add_argument("file", type=Path, help="audio file (wav, flac, ogg/opus, mp3, ...)")
    p.add_argument("--fps", type=int, choices=(30, 60), default=60, help="feature frame rate (default 60)")
    p.add_argument("--out", type=Path, default=None, help="save the (T, 35) features to this .npy file")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--start-bpm", type=float, default=None, help="beat-tracker tempo prior (default: auto)")
    p.add_argument("--cache-dir", type=Path, default=None, help="feature cache folder")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the feature cache")
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``sm analyze-music``; returns the process exit code."""
    args = _parser().parse_args(argv)
    from skeleton_mamba.tasks.motion.music import extract_music_features

    try:
        analysis = extract_music_features(
            args.file,
            fps=args.fps,
            start_bpm=args.start_bpm,
            cache_dir=args.cache_dir,
            use_cache=not args.no_cache,
        )
    except (FileNotFoundError, ValueError) as err:
        print(f"sm analyze-music: error: {err}", file=sys.stderr)
        return 2
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        np.save(args.out, analysis.features, allow_pickle=False)
    beats = [round(float(t), 4) for t in analysis.beat_times]
    if args.json:
        print(
            json.dumps(
                {
                    "file": str(args.file),
                    "duration_s": round(analysis.duration_s, 4),
                    "tempo_bpm": round(analysis.tempo_bpm, 3),
                    "beats_s": beats,
                    "fps": analysis.fps,
                    "feature_shape": list(analysis.features.shape),
                }
            )
        )
    else:
        summary = f"{analysis.duration_s:.2f} s, tempo {analysis.tempo_bpm:.1f} BPM, {len(beats)} beats"
        print(f"{args.file}: {summary}")
        print("beats (s): " + " ".join(f"{t:.3f}" for t in beats))
        if args.out is not None:
            print(f"features {tuple(analysis.features.shape)} @ {analysis.fps} fps -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
