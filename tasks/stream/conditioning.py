"""Does a live dance follow its music? [Bailando]'s BeatAlign over chance on the music's tracked beats.

The margin is BeatAlign minus its chance, the same dance scored against the beat grid shifted by 1/10 ...
9/10 of a beat (:func:`~skeleton_mamba.tasks.motion.metrics.beat_align.beat_align_over_chance`): 0 for a
dance with no relation to the beat, however regular its own. The beats are librosa's tracker on the music at
30 fps (:func:`~skeleton_mamba.tasks.motion.synthetic.recorded_music_set.tracked_beats`, the beats the
recorded-music demo set's dances are choreographed to). The demo's target: the dance's margin on held-out
music at least half its ground truth's (:data:`TARGET_FRACTION`).
"""

from __future__ import annotations

import numpy as np
import torch

from skeleton_mamba.tasks.motion.metrics.beat_align import beat_align_over_chance
from skeleton_mamba.tasks.motion.synthetic.recorded_music_set import tracked_beats
from skeleton_mamba.tasks.stream.features import FPS

__all__ = ["TARGET_FRACTION", "conditioning_scores", "format_conditioning", "margin_over_chance"]

TARGET_FRACTION = 0.5


def margin_over_chance(joints: np.ndarray | torch.Tensor, beats: np.ndarray) -> float:
    """BeatAlign ([Bailando]) of (T, 24, 3) joints on ``beats`` (30 fps frames) minus its shifted-grid
    chance."""
    align, chance = beat_align_over_chance(np.asarray(joints, dtype=np.float64), beats, "bailando", FPS)
    return float(align - chance)


def conditioning_scores(dances: list, truths: list, audios: list[np.ndarray]) -> dict:
    """Mean margins over chance of the dances and their ground truths, each on its music's tracked beats
    (mono audio at the stream's rate), and whether the dances reach half the truths' margin."""
    margins, truth_margins = [], []
    for dance, truth, audio in zip(dances, truths, audios, strict=True):
        beats = tracked_beats(audio)
        beats = beats[beats < min(len(dance), len(truth))]
        margins.append(margin_over_chance(dance, beats))
        truth_margins.append(margin_over_chance(truth, beats))
    margin, truth_margin = float(np.mean(margins)), float(np.mean(truth_margins))
    return {
        "margin": margin,
        "truth_margin": truth_margin,
        "per_sequence": margins,
        "truth_per_sequence": truth_margins,
        "reached": bool(margin >= TARGET_FRACTION * truth_margin),
    }


def format_conditioning(scores: dict) -> str:
    """The dance's margin over chance beside the truth's, and the target as the demos print their checks
    (``reached: ...`` / ``NOT reached: ...``)."""
    verdict = "reached" if scores["reached"] else "NOT reached"
    return (
        f"  beat margin over chance on the held-out music: dance {scores['margin']:+.3f}, ground truth "
        f"{scores['truth_margin']:+.3f}\n"
        f"  {verdict}: beat margin over chance >= {TARGET_FRACTION:g} x the ground truth's"
    )
