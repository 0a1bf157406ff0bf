"""BeatAlign: how well kinematic beats (velocity minima) meet music beats, in both published variants.

The two published definitions ([FACT] and [Bailando]) disagree, so the variant is always named:

``"fact"`` (liruilong940607/mint tools/calculate_beat_scores.py; FACT, QEAN):
    envelope ``e_t = sum_joints |p_t - p_(t-1)|`` with ``e_0 = 0``; motion beats are strict local minima
    of ``e`` over ``+-10`` frames (``scipy.signal.argrelextrema(order=10)``, "10 for 60FPS"); score = mean
    over **motion** beats of ``exp(-d^2 / (2 sigma^2))``, ``d`` = distance to the nearest music beat,
    ``sigma = 3`` frames; 0 when the motion has no beat. Precision-like.
``"bailando"`` (lisiyao21/Bailando utils/beat_align_score.py; Bailando, LODGE, EgoMusic's MM term):
    envelope ``e_t = mean_joints |p_(t+1) - p_t|`` (``T - 1`` values) smoothed with
    ``scipy.ndimage.gaussian_filter(sigma=5)``; motion beats = its local minima (order 1); music beats are
    truncated to the envelope length; score = mean over **music** beats of ``exp(-d^2 / (2 * 9))``,
    ``d`` = distance to the nearest motion beat. Recall-like.

Frame constants are the published 60 fps values; at another ``fps`` they are scaled by ``fps / 60`` so they
keep their meaning in seconds (minima window 1/6 s, sigma 0.05 s, smoothing 1/12 s). FACT scores generated
motion on frames ``>= 120`` (after the seed) with beats found on the whole sequence: ``start_frame=120``;
Bailando scores the whole sequence (``start_frame=0``). Music beats past the motion's end are dropped for
real motion and by Bailando (``get_mb(key, length)``); the FACT script keeps them when it scores generated
motion from frame 120 (``audio_beats[120:]`` of the whole track), which moves the score of a motion beat in
the last frames: ``truncate_music=False``, the default of :class:`BeatAlign` for ``"fact"`` with
``start_frame > 0``. The named protocols of :mod:`.protocols` set all of this.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import torch
from scipy.ndimage import gaussian_filter
from scipy.signal import argrelextrema
from torchmetrics import Metric

from skeleton_mamba.tasks.motion.metrics.common import Positions, as_sequences, beat_indices

__all__ = [
    "CHANCE_SHIFTS",
    "BeatAlign",
    "alignment_score",
    "beat_align_over_chance",
    "kinematic_beats",
    "sequence_beat_align",
    "shifted_beats",
]

Variant = Literal["fact", "bailando"]
_REFERENCE_FPS = 60.0


def kinematic_beats(
    positions: torch.Tensor | np.ndarray, variant: Variant = "bailando", fps: float = 60.0
) -> np.ndarray:
    """Motion-beat frame indices of one ``(T, J, 3)`` joint sequence (velocity minima of ``variant``).

    Pass a single joint as ``(T, 1, 3)`` for the head beats of the MMV metric.

    Examples:
        A joint swinging 1 m at 2 Hz (60 fps) stops at each end of the swing, every 15 frames (FACT's minima
        need 10 frames on either side):

        >>> import numpy as np
        >>> t = np.arange(120)
        >>> swing = np.zeros((120, 1, 3))
        >>> swing[:, 0, 0] = np.sin(2 * np.pi * 2 * t / 60)
        >>> kinematic_beats(swing, "fact").tolist()
        [23, 38, 53, 68, 83, 98, 113]
    """
    p = np.asarray(positions.cpu() if isinstance(positions, torch.Tensor) else positions, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] != 3:
        raise ValueError(f"positions must be (T, J, 3), got {p.shape}")
    scale = fps / _REFERENCE_FPS
    speed = np.linalg.norm(p[1:] - p[:-1], axis=-1)  # (T-1, J)
    if variant == "fact":
        envelope = np.concatenate([[0.0], speed.sum(axis=1)])
        order = max(1, round(10 * scale))
        return argrelextrema(envelope, np.less, order=order)[0]
    if variant == "bailando":
        envelope = gaussian_filter(speed.mean(axis=1), 5 * scale)
        return argrelextrema(envelope, np.less)[0]
    raise ValueError(f"variant must be 'fact' or 'bailando', got {variant!r}")


def alignment_score(queries: np.ndarray, targets: np.ndarray, sigma: float) -> float:
    """``mean_q exp(-min_t (q - t)^2 / (2 sigma^2))`` over beat frames ``queries`` (0.0 if none match).

    Returns 0.0 when either set is empty (no beat to align / nothing to align to).

    Examples:
        >>> round(alignment_score([10, 20], [10, 23], sigma=3.0), 4)  # (1 + exp(-9 / 18)) / 2
        0.8033
        >>> alignment_score([], [10], sigma=3.0)
        0.0
    """
    queries = np.asarray(queries, dtype=np.float64)
    targets = np.asarray(targets, dtype=np.float64)
    if queries.size == 0 or targets.size == 0:
        return 0.0
    nearest = np.abs(queries[:, None] - targets[None, :]).min(axis=1)
    return float(np.exp(-(nearest**2) / (2 * sigma**2)).mean())


def sequence_beat_align(
    positions: torch.Tensor | np.ndarray,
    music_beats: torch.Tensor | np.ndarray | Sequence[int],
    variant: Variant,
    fps: float = 60.0,
    start_frame: int = 0,
    truncate_music: bool = True,
) -> float:
    """BeatAlign of one ``(T, J, 3)`` motion against its music beats (one-hot or frame indices).

    Beats are found on the whole sequence; only motion and music beats at frames ``>= start_frame`` count.
    ``truncate_music`` drops music beats past the motion (``T`` for FACT, the envelope's ``T - 1`` for
    Bailando); ``False`` keeps every beat of the track (FACT's script on generated motion).

    Examples:
        >>> import numpy as np
        >>> t = np.arange(120)
        >>> swing = np.zeros((120, 1, 3))
        >>> swing[:, 0, 0] = np.sin(2 * np.pi * 2 * t / 60)
        >>> on_beat = [23, 38, 53, 68, 83, 98, 113]  # music beats where the motion's are
        >>> round(sequence_beat_align(swing, on_beat, "fact"), 4)
        1.0
        >>> late = [b + 3 for b in on_beat]  # 3 frames late: exp(-3^2 / (2 * 3^2))
        >>> round(sequence_beat_align(swing, late, "fact"), 4)
        0.6065
    """
    motion = kinematic_beats(positions, variant, fps)
    return _score(
        motion, beat_indices(music_beats), variant, fps, len(positions), start_frame, truncate_music
    )


def _score(
    motion: np.ndarray,
    beats: np.ndarray,
    variant: Variant,
    fps: float,
    t: int,
    start_frame: int = 0,
    truncate_music: bool = True,
) -> float:
    """BeatAlign of motion beats against music beats (frames, fractional ones allowed) of a T-frame motion."""
    motion = motion[motion >= start_frame]
    beats = beats[beats >= start_frame]
    sigma = 3.0 * fps / _REFERENCE_FPS
    if variant == "fact":
        if truncate_music:
            beats = beats[beats < t]  # music truncated to the motion length
        return alignment_score(motion, beats, sigma)
    if truncate_music:
        beats = beats[beats < t - 1]  # Bailando: truncated to the envelope length T - 1
    return alignment_score(beats, motion, sigma)


CHANCE_SHIFTS = tuple(k / 10 for k in range(1, 10))
"""Fractions of a beat the music's beat grid is shifted by for :func:`beat_align_over_chance`."""


def shifted_beats(beats: np.ndarray, fraction: float) -> np.ndarray:
    """Beat frames (sorted, at least two) moved ``fraction`` of the way to the next beat (the last one by its
    own interval from the one before): the same grid, off the beat."""
    beats = np.asarray(beats, dtype=np.float64)
    period = np.diff(beats)
    return beats + fraction * np.append(period, period[-1])


def beat_align_over_chance(
    positions: torch.Tensor | np.ndarray,
    music_beats: torch.Tensor | np.ndarray | Sequence[int],
    variant: Variant = "bailando",
    fps: float = 60.0,
) -> tuple[float, float]:
    """BeatAlign of one ``(T, J, 3)`` motion and its chance: the mean BeatAlign of the same motion against the
    music's beat grid shifted by 1/10 ... 9/10 of a beat (:data:`CHANCE_SHIFTS`). Their difference, the margin
    over chance, is 0 for a motion that has no relation to the beat (however regular its own beats) and the
    score's distance above its off-beat value for one that moves on it. NaN chance with fewer than 2 beats.

    Examples:
        A swing that stops every 15 frames, scored against beats on its stops and shifted off them:

        >>> import numpy as np
        >>> t = np.arange(240)
        >>> swing = np.zeros((240, 1, 3))
        >>> swing[:, 0, 0] = np.sin(2 * np.pi * 2 * t / 60)
        >>> score, chance = beat_align_over_chance(swing, list(range(8, 240, 15)), "fact")
        >>> round(score, 3), round(chance, 3)
        (1.0, 0.438)
    """
    motion = kinematic_beats(positions, variant, fps)
    beats = beat_indices(music_beats)
    t = len(positions)
    score = _score(motion, beats, variant, fps, t)
    if beats.size < 2:
        return score, float("nan")
    chance = [_score(motion, shifted_beats(beats, f), variant, fps, t) for f in CHANCE_SHIFTS]
    return score, float(np.mean(chance))


class BeatAlign(Metric):
    """Beat alignment score averaged over sequences, ``variant="fact"`` or ``"bailando"`` (see module doc).

    Args:
        variant: ``"fact"`` (averaged over motion beats) or ``"bailando"`` (averaged over music beats).
        fps: frame rate of motion and beats (published constants are for 60 fps and scale with it).
        start_frame: score only beats from this frame on (FACT generated motion: 120, after the seed).
        truncate_music: drop music beats past the motion's end; ``None``: ``False`` for ``"fact"`` with
            ``start_frame > 0`` (FACT's script on generated motion), else ``True``.

    ``update(positions, music_beats)`` takes ``(B, T, J, 3)`` joints (or a list of ``(T_i, J, 3)``) and one
    beat vector per sequence: one-hot ``(T,)`` (column 34 of the music features) or frame indices.

    Examples:
        >>> import torch
        >>> t = torch.arange(120.0)
        >>> swing = torch.zeros(1, 120, 1, 3)
        >>> swing[0, :, 0, 0] = torch.sin(2 * torch.pi * 2 * t / 60)
        >>> metric = BeatAlign("fact")
        >>> metric.update(swing, [[23, 38, 53, 68, 83, 98, 113]])
        >>> round(float(metric.compute()), 4)
        1.0
    """

    is_differentiable = False
    higher_is_better = True
    full_state_update = False

    def __init__(
        self,
        variant: Variant = "bailando",
        fps: float = 60.0,
        start_frame: int = 0,
        truncate_music: bool | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        if variant not in ("fact", "bailando"):
            raise ValueError(f"variant must be 'fact' or 'bailando', got {variant!r}")
        self.variant = variant
        self.fps = fps
        self.start_frame = start_frame
        fact_generated = variant == "fact" and start_frame > 0
        self.truncate_music = not fact_generated if truncate_music is None else truncate_music
        self.add_state("score_sum", default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("count", default=torch.tensor(0, dtype=torch.long), dist_reduce_fx="sum")

    def update(self, positions: Positions, music_beats: Sequence[Any] | torch.Tensor | np.ndarray) -> None:
        sequences = as_sequences(positions, min_frames=3)
        if len(music_beats) != len(sequences):
            raise ValueError(f"got {len(sequences)} motions but {len(music_beats)} beat vectors")
        for seq, beats in zip(sequences, music_beats, strict=True):
            self.score_sum += sequence_beat_align(
                seq, beats, self.variant, self.fps, self.start_frame, self.truncate_music
            )
            self.count += 1

    def compute(self) -> torch.Tensor:
        if self.count == 0:
            raise RuntimeError("BeatAlign.compute() called before any update()")
        return self.score_sum / self.count
