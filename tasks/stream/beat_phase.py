"""A causal beat tracker for the live dancer: where in the beat the music is now, from the past alone.

The dancer's output low-pass delays its motion (``stages d / (1 - d)`` frames), and a pose that waits for the
beat's onset stops after it. With the phase of the beat as an input it can stop *on* the next beat: the
phase advances by one over a beat period, so the frames until the next beat are known before it sounds.

Per 30 fps frame, from the onset strength of the last :data:`HISTORY` frames (8 s) (column 0 of
:mod:`.features`, mean-removed):

* tempo: the lag in :data:`LAGS` (180 to 40 BPM) of the largest autocorrelation of the history weighted by a
  log-normal tempo prior about 120 BPM (one octave's deviation, as librosa's tracker), refined to a
  fractional period by a parabola through the neighbouring lags;
* phase: the offset ``o`` in ``[0, period)`` whose comb of frames ``t - o - k * period`` (k = 0, 1, ...,
  linearly interpolated, weights decaying by half every four beats) holds the most onset strength: the
  last beat was ``o`` frames ago, so the phase is ``o / period`` (0 on a beat, rising to 1 at the next).

The two columns are ``cos`` and ``sin`` of ``2 pi phase``, times the tracker's confidence (the prior-weighted
autocorrelation at the tempo over the history's energy, clipped to [0, 1]; 0 before :data:`MIN_HISTORY`
frames or in silence). Nothing looks ahead: frame t reads the onsets up to t.
"""

from __future__ import annotations

import numpy as np

__all__ = ["HISTORY", "LAGS", "MIN_HISTORY", "NUM_BEAT_FEATURES", "CausalBeatPhase", "beat_phase_features"]

HISTORY = 240  # 8 s at 30 fps (librosa's tempo window)
MIN_HISTORY = 60  # 2 s before the first estimate
LAGS = np.arange(10, 46)  # beat periods of 10 ... 45 frames: 180 ... 40 BPM at 30 fps
NUM_BEAT_FEATURES = 2
_PRIOR = np.exp(-0.5 * np.log2((60.0 * 30 / LAGS) / 120.0) ** 2)  # log-normal about 120 BPM, 1 octave
_DECAY_BEATS = 4.0


class CausalBeatPhase:
    """Push onset strengths (one per frame) in, get ``(n, 2)`` phase features out (module docstring)."""

    def __init__(self) -> None:
        self.history = np.zeros(0, dtype=np.float64)

    def push(self, onsets: np.ndarray) -> np.ndarray:
        """The ``(len(onsets), 2)`` float32 features of frames whose onset strengths are ``onsets``."""
        out = np.zeros((len(onsets), NUM_BEAT_FEATURES), dtype=np.float32)
        for i, onset in enumerate(np.asarray(onsets, dtype=np.float64).reshape(-1)):
            self.history = np.append(self.history, onset)[-HISTORY:]
            out[i] = self._estimate()
        return out

    def _estimate(self) -> tuple[float, float]:
        h = self.history
        if len(h) < MIN_HISTORY:
            return 0.0, 0.0
        x = h - h.mean()
        energy = float(x @ x)
        if energy <= 1e-12:
            return 0.0, 0.0
        lags = LAGS[LAGS < len(x) // 2]
        corr = np.array([x[lag:] @ x[:-lag] / (len(x) - lag) for lag in lags]) * len(x) / energy
        weighted = corr * _PRIOR[: len(lags)]
        best = int(np.argmax(weighted))
        period = float(lags[best])
        if 0 < best < len(lags) - 1:
            a, b, c = weighted[best - 1 : best + 2]
            denominator = a - 2 * b + c
            if denominator < 0:
                period += float(np.clip(0.5 * (a - c) / denominator, -0.5, 0.5))
        confidence = float(np.clip(weighted[best], 0.0, 1.0))
        offsets = np.arange(int(np.ceil(period)))
        beats = np.arange(int(len(h) // period) + 1)
        positions = (len(h) - 1) - offsets[:, None] - beats[None] * period  # frames back from now
        weights = 0.5 ** (beats / _DECAY_BEATS)
        valid = positions >= 0
        values = np.interp(np.where(valid, positions, 0.0), np.arange(len(h)), h)
        strength = (values * valid * weights).sum(axis=1)
        since = float(offsets[int(np.argmax(strength))])
        phase = 2 * np.pi * since / period
        return confidence * float(np.cos(phase)), confidence * float(np.sin(phase))


def beat_phase_features(onsets: np.ndarray) -> np.ndarray:
    """The phase features ``(T, 2)`` of a whole onset-strength sequence (T,), as a live stream yields them."""
    return CausalBeatPhase().push(onsets)
