"""``sm analyze-music FILE``: tempo, beat times and the 35-d music features of one audio file.

The tempo is the one detected in the beats; the same tempo folded by octaves into the dance range
80-170 BPM is printed beside it, labelled (``dance_tempo_bpm`` in JSON): a 68 BPM track reads "tempo
68.0 BPM (dance range 80-170 BPM: 136.0)". Audio without a tempo (silent, shorter than 2 s, no steady
beat) says so, and its tempo is ``null`` in JSON. ``--out`` must name a ``.npy`` file, written atomically
to exactly that path. Undecodable audio or samples out of range end with one line naming the file (exit 2).

Examples::

    sm analyze-music song.opus                    # tempo and beat times at 60 fps
    sm analyze-music song.wav --fps 30 --out f.npy  # EDGE's 30 fps features saved as (T, 35) .npy
    sm analyze-music song.mp3 --json              # one JSON object on stdout

The JSON object records the audio stack (``audio_stack``: librosa, numpy, soundfile versions and the
resampler, :func:`skeleton_mamba.tasks.motion.music.features.audio_stack`): beat frames differ between librosa
versions.
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.tasks.motion.commands.analyze_music_args import build_parser
from skeleton_mamba.tasks.motion.music.features import (
    DANCE_BPM_RANGE,
    ENVELOPE,
    OCTAVE_AMBIGUITY,
    audio_stack,
    extract_music_features,
    tempo_octaves,
)
from skeleton_mamba.tasks.motion.music.jit_lock import librosa_calls

__all__ = ["main"]


def _check_out(out: Path) -> str | None:
    """Why ``--out`` cannot be written as given (``None`` when it can)."""
    if out.is_dir():
        return f"--out {out} is a folder; give a .npy file name"
    if out.suffix.lower() != ".npy":
        return f"--out {out} must end in .npy (numpy would write {out}.npy instead)"
    return None


def _analyse(args: argparse.Namespace):
    """The analysis of ``args.file``.

    Raises:
        InputError: the audio cannot be analysed (the one-line message names the file).
    """
    with librosa_calls() as librosa:  # its exception class (and the import under the compile lock)
        parameter_error = librosa.util.exceptions.ParameterError
    try:
        with warnings.catch_warnings():  # librosa's CQT notes, overflow warnings: errors are one line
            warnings.simplefilter("ignore", RuntimeWarning)
            warnings.simplefilter("ignore", UserWarning)
            return extract_music_features(
                args.file,
                fps=args.fps,
                start_bpm=args.start_bpm,
                cache_dir=args.cache_dir,
                use_cache=not args.no_cache,
            )
    except (FileNotFoundError, ValueError) as err:  # messages name the file
        raise InputError(str(err)) from err
    except parameter_error as err:
        # decoded, then overflowed inside the analysis: samples far outside [-1, 1] (e.g. 1e30)
        raise InputError(
            f"{args.file}: samples out of range, the analysis overflows ({err}); audio lies in [-1, 1]"
        ) from err


def _close(octaves: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The octaves nearly as strong as the strongest (:data:`OCTAVE_AMBIGUITY`), strongest first."""
    return [(b, s) for b, s in octaves if s >= OCTAVE_AMBIGUITY * octaves[0][1]]


def _ambiguous(tempo: float | None, octaves: list[tuple[float, float]]) -> bool:
    """Whether another octave of ``tempo`` is nearly as strong as the strongest."""
    if tempo is None or len(octaves) < 2 or octaves[0][1] <= 0:
        return False
    close = _close(octaves)
    return len(close) > 1 or close[0][0] != tempo


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``sm analyze-music``; returns the process exit code."""
    args = build_parser().parse_args(argv)
    problem = None if args.out is None else _check_out(args.out)
    if problem is not None:
        raise InputError(problem)
    analysis = _analyse(args)
    if args.out is not None:
        try:
            with atomic_open(args.out, "wb") as f:  # exactly args.out: np.save on a handle adds no suffix
                np.save(f, np.ascontiguousarray(analysis.features), allow_pickle=False)
        except OSError as err:
            raise InputError(f"{args.out}: cannot write ({err.strerror or err})") from err
    beats = [round(float(t), 4) for t in analysis.beat_times]
    tempo, dance = analysis.tempo_bpm, analysis.dance_tempo_bpm
    octaves = [] if tempo is None else tempo_octaves(analysis.features[:, ENVELOPE], analysis.fps, tempo)
    if args.json:
        report = {
            "file": str(args.file),
            "duration_s": round(analysis.duration_s, 4),
            "tempo_bpm": None if tempo is None else round(tempo, 3),
            "dance_tempo_bpm": None if dance is None else round(dance, 3),
            "dance_bpm_range": list(DANCE_BPM_RANGE),
            "tempo_octaves": [{"bpm": round(b, 3), "strength": round(s, 3)} for b, s in octaves],
            "tempo_ambiguous": _ambiguous(tempo, octaves),
            "beats_s": beats,
            "fps": analysis.fps,
            "feature_shape": list(analysis.features.shape),
        }
        if analysis.tempo_note:
            report["tempo_note"] = analysis.tempo_note
        report["audio_stack"] = audio_stack()
        print(json.dumps(report))
    else:
        low, high = DANCE_BPM_RANGE
        if tempo is None:
            tempo_text = f"no tempo: {analysis.tempo_note}"
        else:
            tempo_text = f"tempo {tempo:.1f} BPM (dance range {low:g}-{high:g} BPM: {dance:.1f})"
        print(f"{args.file}: {analysis.duration_s:.2f} s, {tempo_text}, {len(beats)} beats")
        if _ambiguous(tempo, octaves):
            print(
                "tempo octaves (onset periodicity weighed by the tempo prior): "
                + ", ".join(f"{b:.1f} BPM {s:.2f}" for b, s in _close(octaves))
                + f"; the beat tracker chose {tempo:.1f}: --start-bpm near another one chooses that octave"
            )
        print("beats (s): " + " ".join(f"{t:.3f}" for t in beats))
        if args.out is not None:
            print(f"features {tuple(analysis.features.shape)} @ {analysis.fps} fps -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
