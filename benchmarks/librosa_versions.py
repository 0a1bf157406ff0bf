"""Benchmark: how far music beats and BeatAlign move between two audio stacks (librosa 0.9 -> 0.11).

The protocol beat recipes (``fact``: the 60 fps 35-d beat column; ``bailando``: the HPSS-percussive
``beat_track``; ``edge``: the per-slice 30 fps beat column) run, through the same code
(``skeleton_mamba.tasks.motion.music.protocol_music``), under this interpreter's stack and under a second
interpreter (``--old-python``: a venv with the references' stack, e.g. numpy 1.26.4, librosa 0.9.2,
resampy 0.4.3, whose default resampler is resampy's ``kaiser_best``; librosa >= 0.10 defaults to
``soxr_hq``). Reported per protocol, pooled over the tracks (and EDGE's slices):

* ``beats_old`` / ``beats_new``: beat counts;
* ``differ``: fraction of beat frames not in both sets, ``|A ^ B| / |A | B|``;
* ``unmatched_within_1``: of the beats of either set not in the other, the fraction with a beat of the
  other set one frame away.

BeatAlign: no AIST++ motion is available here, so each track gets one fixed motion, a synthetic SMPL-24
dance (``synthesize_dance``, 60 fps, the full track length) at the track's tempo (from the new stack's
FACT beats, folded into 80-170 BPM), scored by the protocol (``get_protocol(p).score``, generated motion)
against the old and the new beats; ``beat_align_old`` / ``beat_align_new`` / ``delta`` per track and
``max_abs_delta`` per protocol. The second interpreter needs no torch: only the beat code is imported
there, with two API shims for librosa < 0.10 (``librosa.feature.tempo`` = ``librosa.beat.tempo``;
``get_duration(path=)`` = ``get_duration(filename=)``), which rename functions and change no numbers.

Usage::

    python benchmarks/librosa_versions.py --old-python /tmp/old_stack/bin/python [--json]
        [--music-dir ../shared/data/music]
"""

from __future__ import annotations

import argparse
import inspect
import json
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT_MUSIC = REPO.parent / "shared" / "data" / "music"
AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".opus", ".mp3")
PROTOCOLS = ("fact", "bailando", "edge")


def _import_beat_code():
    """``protocol_music`` and ``music``: installed, or from this checkout without the torch package."""
    try:
        import skeleton_mamba.tasks.motion.music.protocol_music as protocol_music
    except ImportError:  # a bare venv: register the two parent packages without running their __init__
        for name, folder in (
            ("skeleton_mamba", REPO / "skeleton_mamba"),
            ("skeleton_mamba.tasks", REPO / "tasks"),
        ):
            module = types.ModuleType(name)
            module.__path__ = [str(folder)]
            sys.modules[name] = module
        import skeleton_mamba.tasks.motion.music.protocol_music as protocol_music
    import librosa

    if not hasattr(librosa.feature, "tempo"):  # librosa < 0.10: same function, older home
        librosa.feature.tempo = librosa.beat.tempo
    if "path" not in inspect.signature(librosa.get_duration).parameters:  # librosa < 0.10: filename=
        original = librosa.get_duration

        def get_duration(*args, path=None, **kwargs):
            return original(*args, filename=path, **kwargs) if path is not None else original(*args, **kwargs)

        librosa.get_duration = get_duration
    from skeleton_mamba.tasks.motion.music import features as music

    return protocol_music, music


def compute_beats(tracks: list[Path]) -> dict:
    """Beat frames of every protocol for every track under this interpreter, with its audio stack."""
    protocol_music, music = _import_beat_code()
    out = {"audio_stack": music.audio_stack(), "python": sys.version.split()[0], "tracks": {}}
    with tempfile.TemporaryDirectory() as cache:  # no cache shared between stacks or runs
        for track in tracks:
            start = time.perf_counter()
            edge = protocol_music.edge_slice_features(track, cache_dir=cache, use_cache=False)
            out["tracks"][track.name] = {
                "fact": protocol_music.fact_beats(track, cache_dir=cache).tolist(),
                "bailando": protocol_music.bailando_beats(track, cache_dir=cache, use_cache=False).tolist(),
                "edge": [b.tolist() for b in protocol_music.edge_slice_beats(edge)],
                "seconds": round(time.perf_counter() - start, 2),
            }
    return out


def _frame_sets(beats, protocol: str) -> set:
    if protocol == "edge":
        return {(i, int(f)) for i, frames in enumerate(beats) for f in frames}
    return {int(f) for f in beats}


def _near(item, other: set) -> bool:
    if isinstance(item, tuple):
        return (item[0], item[1] - 1) in other or (item[0], item[1] + 1) in other
    return item - 1 in other or item + 1 in other


def compare(old: dict, new: dict, tracks: list[Path]) -> dict:
    """Beat differences per protocol and BeatAlign of a fixed synthetic dance against both beat sets."""
    import librosa
    import numpy as np

    from skeleton_mamba.tasks.motion.metrics.protocols import get_protocol
    from skeleton_mamba.tasks.motion.music.features import fold_tempo, tempo_from_beats
    from skeleton_mamba.tasks.motion.synthetic import synthesize_dance

    summary = {
        p: {"beats_old": 0, "beats_new": 0, "differ_count": 0, "union": 0, "near": 0} for p in PROTOCOLS
    }
    per_track, paths = {}, {t.name: t for t in tracks}
    for name, new_beats in new["tracks"].items():
        old_beats = old["tracks"][name]
        row = {}
        for p in PROTOCOLS:
            a, b = _frame_sets(old_beats[p], p), _frame_sets(new_beats[p], p)
            sym = a ^ b
            s = summary[p]
            s["beats_old"] += len(a)
            s["beats_new"] += len(b)
            s["differ_count"] += len(sym)
            s["union"] += len(a | b)
            s["near"] += sum(_near(x, b if x in a else a) for x in sym)
            row[p] = {"differ": round(len(sym) / max(len(a | b), 1), 4)}
        duration = float(librosa.get_duration(path=paths[name]))
        bpm = fold_tempo(tempo_from_beats(np.asarray(new_beats["fact"]), 60.0))
        joints = synthesize_dance(bpm, duration, fps=60.0, style="bounce", seed=0).joint_positions()
        for p in PROTOCOLS:
            protocol = get_protocol(p)
            scores = []
            for beats in (old_beats[p], new_beats[p]):
                beats = [np.asarray(b) for b in beats] if p == "edge" else np.asarray(beats)
                clips = protocol.score(joints, 60.0, beats, generated=True)
                scores.append(float(np.mean([c.beat_align for c in clips])))
            row[p].update(beat_align_old=round(scores[0], 5), beat_align_new=round(scores[1], 5),
                          delta=round(scores[1] - scores[0], 5))  # fmt: skip
        row["dance_bpm"] = round(bpm, 2)
        per_track[name] = row
    protocols = {}
    for p, s in summary.items():
        deltas = [abs(per_track[t][p]["delta"]) for t in per_track]
        protocols[p] = {
            "beats_old": s["beats_old"],
            "beats_new": s["beats_new"],
            "differ": round(s["differ_count"] / max(s["union"], 1), 4),
            "unmatched_within_1": round(s["near"] / max(s["differ_count"], 1), 4),
            "max_abs_delta_beat_align": round(max(deltas), 5),
        }
    return {"protocols": protocols, "tracks": per_track}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--old-python", type=Path, help="interpreter of the other audio stack (a venv's python)")
    p.add_argument("--music-dir", type=Path, default=DEFAULT_MUSIC)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--beats-out", type=Path, help=argparse.SUPPRESS)  # worker mode: write beats, exit
    args = p.parse_args(argv)
    tracks = sorted(f for f in args.music_dir.glob("*") if f.suffix.lower() in AUDIO_SUFFIXES)
    if not tracks:
        print(f"no audio files in {args.music_dir}", file=sys.stderr)
        return 2
    if args.beats_out is not None:
        args.beats_out.write_text(json.dumps(compute_beats(tracks)))
        return 0
    if args.old_python is None:
        p.error("--old-python is required (the second audio stack's interpreter)")
    with tempfile.TemporaryDirectory() as tmp:
        beats_file = Path(tmp) / "old.json"
        cmd = [
            str(args.old_python),
            __file__,
            "--music-dir",
            str(args.music_dir),
            "--beats-out",
            str(beats_file),
        ]
        subprocess.run(cmd, check=True, cwd=tmp)
        old = json.loads(beats_file.read_text())
    new = compute_beats(tracks)
    result = {
        "benchmark": "librosa_versions",
        "old_stack": {**old["audio_stack"], "python": old["python"]},
        "new_stack": {**new["audio_stack"], "python": new["python"]},
        "tracks": [t.name for t in tracks],
        "motion": "synthetic SMPL-24 dance at each track's tempo (no AIST++ motion available)",
        **compare(old, new, tracks),
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"old stack: {result['old_stack']}\nnew stack: {result['new_stack']}")
        for name, row in result["protocols"].items():
            print(f"{name:9s} {row}")
        for name, row in result["tracks"].items():
            print(f"{name}: {row}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
