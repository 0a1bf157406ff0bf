"""Does a generated dance follow its music? [Bailando]'s BeatAlign over chance, beside the ground truth's.

The margin is BeatAlign minus its chance, the same dance scored against the beat grid shifted by 1/10 ...
9/10 of a beat (:func:`~skeleton_mamba.tasks.motion.metrics.beat_align.beat_align_over_chance`): 0 for a
dance with no relation to the beat, however regular its own. The dancing demos (the live dancer, QEAN) score
their held-out dances and the ground truth over the same frames against the same music beats; their target:
the dance's margin at least half the truth's (:data:`TARGET_FRACTION`). A dance that follows the music as
well as its truth reaches it; one that ignores the music sits at 0.

Examples:
    A swing that stops on every beat, and one that stops half a beat off, against the same truth:

    >>> import numpy as np
    >>> t = np.arange(240)
    >>> def swing(shift):
    ...     x = np.zeros((240, 1, 3))
    ...     x[:, 0, 0] = np.sin(2 * np.pi * 2 * (t - shift) / 60)
    ...     return x
    >>> beats = np.arange(8, 240, 15)
    >>> on, off = (conditioning_scores([swing(s)], [swing(0)], [beats], 60.0) for s in (0, 7))
    >>> on["reached"], off["reached"], on["margin"] > 0.3 > off["margin"]
    (True, False, True)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from skeleton_mamba.tasks.motion.metrics.beat_align import beat_align_over_chance

__all__ = ["TARGET_FRACTION", "conditioning_scores", "format_conditioning", "margin_over_chance"]

TARGET_FRACTION = 0.5


def margin_over_chance(joints: np.ndarray | torch.Tensor, beats: np.ndarray, fps: float) -> float:
    """BeatAlign ([Bailando]) of (T, J, 3) joints at ``fps`` on ``beats`` (frames) minus its shifted-grid
    chance."""
    align, chance = beat_align_over_chance(np.asarray(joints, dtype=np.float64), beats, "bailando", fps)
    return float(align - chance)


def conditioning_scores(dances: Sequence, truths: Sequence, beats: Sequence[np.ndarray], fps: float) -> dict:
    """Mean margins over chance of the dances (T, J, 3) and their ground truths, each pair over the frames
    both have and on its music's beat frames among them, and whether the dances reach
    :data:`TARGET_FRACTION` of the truths' margin. A sequence with fewer than two beats has no chance
    (NaN margins) and is left out of the means."""
    margins, truth_margins = [], []
    for dance, truth, frames in zip(dances, truths, beats, strict=True):
        length = min(len(dance), len(truth))
        frames = np.asarray(frames, dtype=np.int64)
        frames = frames[(frames >= 0) & (frames < length)]
        margins.append(margin_over_chance(dance[:length], frames, fps))
        truth_margins.append(margin_over_chance(truth[:length], frames, fps))
    scored = np.isfinite(margins) & np.isfinite(truth_margins)
    margin = float(np.mean(np.asarray(margins)[scored])) if scored.any() else float("nan")
    truth_margin = float(np.mean(np.asarray(truth_margins)[scored])) if scored.any() else float("nan")
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
