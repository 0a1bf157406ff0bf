"""``sm evaluate-dance GENERATED_DIR REAL_DIR --protocol fact|bailando|edge``: dance metrics over files.

Examples::

    sm evaluate-dance outputs/ aist_plusplus_final/motions --protocol bailando --music-dir aist/music
    sm evaluate-dance edge_clips/ aist_plusplus_final/motions --protocol edge --music-dir aist/music --json

Both folders hold SMPL-24 motions: our ``.npz`` files (``joints``, or SMPL parameters through forward
kinematics) or AIST++ ``motions/*.pkl`` (read with the restricted unpickler). Every file is scored under the
named protocol (:mod:`skeleton_mamba.tasks.motion.metrics.protocols`: frames, root handling, music beats and
BeatAlign form of [FACT], [Bailando] or [EDGE]); REAL_DIR is the reference set of FID and of the normalisation
of Div (the published codes use every AIST++ sequence minus the ignore list, full length). With
``--music-dir``, each motion's music is ``<music id>.wav`` from an AIST++ name in its file name, else the
audio file with the same stem, and every motion starts with its music; BeatAlign is then reported for both
sets. Prints a table, or one JSON object with ``--json``. Under :data:`MIN_CLIPS` clips in either set a
warning says the FIDs are unreliable (``warnings`` in the JSON, a line on stderr). (EDGE's own output pickles,
z-up at 30 fps without ``smpl_scaling``, are not AIST++ files: convert them to our ``.npz`` first.)
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path

from tqdm import tqdm

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.motion.commands.evaluate_dance_args import build_parser
from skeleton_mamba.tasks.motion.formats.aistpp import music_id
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints
from skeleton_mamba.tasks.motion.metrics.evaluation import DanceEvaluation
from skeleton_mamba.tasks.motion.music.features import audio_stack

__all__ = ["MIN_CLIPS", "evaluate_folders", "main", "sample_size_warnings"]

# Fewest clips per set for a FID worth reading: the 20 sequences of AIST++'s test set, over which FACT and
# Bailando report (fewer clips than the 72-d kinetic and 32-d geometric features have dimensions already
# leave the covariances rank-deficient; a handful of clips gives FIDs in the thousands).
MIN_CLIPS = 20

MOTION_SUFFIXES = (".npz", ".pkl")
AUDIO_SUFFIXES = (".wav", ".mp3", ".flac", ".ogg", ".opus", ".m4a")
_ROWS = ("FID_k", "FID_g", "Div_k", "Div_g", "BeatAlign", "PFC")


class EvaluateDanceError(InputError):
    """An input folder or file cannot be evaluated (the message names it; ``sm`` prints it, exit 2)."""


def _motion_files(folder: Path) -> list[Path]:
    if not folder.is_dir():
        raise EvaluateDanceError(f"{folder}: no such folder")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in MOTION_SUFFIXES and p.is_file())
    if not files:
        raise EvaluateDanceError(f"{folder}: no motion files ({', '.join(MOTION_SUFFIXES)})")
    return files


def _music_for(motion: Path, music_dir: Path) -> Path:
    """``<music id>.<ext>`` for an AIST++ name in the motion's file name, else the audio with its stem."""

    try:
        stems = [music_id(motion.stem), motion.stem]
    except ValueError:  # not an AIST++ sequence name
        stems = [motion.stem]
    for stem in stems:
        for suffix in AUDIO_SUFFIXES:
            candidate = music_dir / f"{stem}{suffix}"
            if candidate.is_file():
                return candidate
    raise EvaluateDanceError(f"{motion}: no music in {music_dir} (looked for {', '.join(stems)}.wav ...)")


def _joints(path: Path):

    try:
        clip = load_joints(path)
    except (OSError, ValueError) as err:  # MotionFileError, UnsafePickleError are ValueErrors
        raise EvaluateDanceError(str(err) if str(path) in str(err) else f"{path}: {err}") from err
    if clip.joints.ndim != 3 or clip.joints.shape[1:] != (24, 3):
        raise EvaluateDanceError(f"{path}: needs SMPL-24 joints (T, 24, 3), got {clip.joints.shape}")
    return clip.joints, clip.fps


def evaluate_folders(
    generated: Path,
    real: Path,
    protocol: str = "fact",
    music_dir: Path | None = None,
    cache_dir: Path | None = None,
    progress: bool = True,
) -> dict:
    """Score every motion of ``generated`` against the reference set ``real`` under ``protocol``.

    Returns:
        The :meth:`skeleton_mamba.tasks.motion.metrics.evaluation.DanceEvaluation.compute` dict plus
        ``protocol``, file counts and ``audio_stack``
        (:func:`skeleton_mamba.tasks.motion.music.features.audio_stack`: the versions that decide the music
        beats).
    """

    evaluation = DanceEvaluation(protocol)
    sets = (("generated", _motion_files(generated)), ("real", _motion_files(real)))
    for side, files in sets:
        for path in tqdm(files, desc=f"{protocol}: {side}", disable=not progress):
            joints, fps = _joints(path)
            beats = None
            if music_dir is not None:
                music = _music_for(path, music_dir)
                try:
                    beats = evaluation.protocol.music_beats(music, cache_dir=cache_dir)
                except (FileNotFoundError, ValueError) as err:
                    raise EvaluateDanceError(f"{music}: {err}") from err
            try:
                evaluation.add(joints, fps, beats, real=side == "real")
            except ValueError as err:
                raise EvaluateDanceError(f"{path}: {err}") from err
    counts = {"generated_files": len(sets[0][1]), "real_files": len(sets[1][1])}
    values = evaluation.compute()
    if "FID_k" not in values:
        raise EvaluateDanceError(
            f"{generated} / {real}: FID and Div need at least 2 clips in each set, got "
            f"{values['generated_clips']} generated and {values['real_clips']} real"
        )

    result = {"protocol": protocol, **counts, **values, "audio_stack": audio_stack()}
    result["warnings"] = sample_size_warnings(result)
    return result


def sample_size_warnings(result: dict) -> list[str]:
    """One warning per set of fewer than :data:`MIN_CLIPS` clips."""
    return [
        f"only {result[key]} {side} clips: FID and Div need at least {MIN_CLIPS} per set to be read (the "
        "AIST++ test set's 20 sequences); these figures are dominated by the sample's noise"
        for side, key in (("generated", "generated_clips"), ("real", "real_clips"))
        if result[key] < MIN_CLIPS
    ]


def format_table(result: dict) -> str:
    """The metrics as a two-column table (generated, real) headed by the protocol and the counts."""
    lines = [
        f"protocol {result['protocol']}: {result['generated_files']} generated files "
        f"({result['generated_clips']} clips), {result['real_files']} real files "
        f"({result['real_clips']} clips)",
        f"{'metric':<10} {'generated':>12} {'real':>12}",
    ]
    for name in _ROWS:
        if name not in result:
            continue
        real = result.get(f"{name}_real")
        real_text = f"{real:>12.6g}" if real is not None else f"{'-':>12}"
        lines.append(f"{name:<10} {result[name]:>12.6g} {real_text}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm evaluate-dance``; returns the exit code."""
    args = build_parser().parse_args(argv)
    result = evaluate_folders(
        args.generated, args.real, args.protocol, args.music_dir, args.cache_dir, args.progress
    )
    for warning in result["warnings"]:
        print(f"sm evaluate-dance: warning: {warning}", file=sys.stderr)
    print(json.dumps(result) if args.json else format_table(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
