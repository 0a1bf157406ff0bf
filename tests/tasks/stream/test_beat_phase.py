"""The live dancer's causal beat phase (tasks/stream/beat_phase.py): on a steady beat it is 0 on the beats and
rises through the beat; it reads nothing ahead; the 36-column features stream as they are computed offline."""

from __future__ import annotations

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.synthetic import synthesize_music
from skeleton_mamba.tasks.stream.beat_phase import MIN_HISTORY, beat_phase_features
from skeleton_mamba.tasks.stream.features import (
    SR,
    CausalMusicFeatures,
    beat_phase_for,
    feature_width,
    music_features,
)


def test_the_phase_of_a_steady_pulse_is_zero_on_its_beats():
    period = 15  # 120 BPM at 30 fps
    onsets = np.zeros(300)
    onsets[::period] = 1.0
    features = beat_phase_features(onsets)
    assert not features[: MIN_HISTORY - 1].any()  # no estimate before two seconds of onsets
    phase = np.angle(features[:, 0] + 1j * features[:, 1]) % (2 * np.pi) / (2 * np.pi)
    beats = np.arange(0, 300, period)
    late = beats[beats >= MIN_HISTORY]
    np.testing.assert_allclose(phase[late], 0.0, atol=1e-3)
    np.testing.assert_allclose(phase[late + 5], 5 / period, atol=1e-3)  # a third of the way to the next beat
    assert np.hypot(features[late, 0], features[late, 1]).min() > 0.5  # a confident estimate


def test_the_phase_reads_nothing_ahead():
    rng = np.random.default_rng(0)
    onsets = rng.random(200)
    changed = onsets.copy()
    changed[150:] = rng.random(50)
    np.testing.assert_array_equal(beat_phase_features(onsets)[:150], beat_phase_features(changed)[:150])


def test_the_streamed_features_with_the_phase_equal_the_offline_ones():
    audio = synthesize_music(110.0, 4.0, sr=22050, seed=1).audio
    offline = music_features(audio, 22050, beat_phase=True)
    assert offline.shape[1] == feature_width(True) == 36
    np.testing.assert_array_equal(offline[:, :34], music_features(audio, 22050))
    live = CausalMusicFeatures(22050, beat_phase=True)
    rows = [live.push(audio[s : s + 1000]) for s in range(0, len(audio), 1000)]
    rows.append(live.push(np.zeros(0, np.float32), last=True))
    np.testing.assert_array_equal(np.concatenate(rows), offline)
    assert beat_phase_for(34) is False and beat_phase_for(36) is True
    with pytest.raises(ValueError, match="34 or 36"):
        beat_phase_for(35)
    assert SR == 15360
