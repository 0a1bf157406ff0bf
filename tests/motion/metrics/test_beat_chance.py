"""BeatAlign against chance: the same motion scored against the music's beat grid shifted off the beat."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.metrics.beat_align import (
    CHANCE_SHIFTS,
    beat_align_over_chance,
    sequence_beat_align,
    shifted_beats,
)


def _swing(frames: int, hz: float, fps: float = 60.0) -> np.ndarray:
    t = np.arange(frames)
    out = np.zeros((frames, 1, 3))
    out[:, 0, 0] = np.sin(2 * np.pi * hz * t / fps)
    return out


def test_shifted_beats_move_each_beat_towards_the_next():
    np.testing.assert_allclose(shifted_beats(np.array([0, 10, 30]), 0.5), [5.0, 20.0, 40.0])
    assert CHANCE_SHIFTS == pytest.approx([k / 10 for k in range(1, 10)])


def test_chance_of_a_swing_on_the_beat_is_the_mean_over_the_shifted_grids():
    """Motion beats every 15 frames on the music's beats (FACT: mean over motion beats, sigma 3 frames): the
    grid shifted by f of a beat lies min(15 f, 15 (1 - f)) frames from every motion beat."""
    beats = list(range(8, 480, 15))
    score, chance = beat_align_over_chance(_swing(480, 2.0), beats, "fact", 60.0)
    expected = np.mean([math.exp(-(min(15 * f, 15 * (1 - f)) ** 2) / 18) for f in CHANCE_SHIFTS])
    assert score == pytest.approx(1.0)
    assert score == pytest.approx(sequence_beat_align(_swing(480, 2.0), beats, "fact", 60.0))
    assert chance == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("variant", ["fact", "bailando"])
def test_a_motion_unrelated_to_the_beat_has_no_margin(variant):
    """A swing at 2 Hz against beats at 1.37 per second: each beat meets the motion's stops at every phase,
    so the score equals its chance (the plain BeatAlign is well above 0 all the same)."""
    beats = np.round(np.arange(0.3, 60.0, 1 / 1.37) * 60).astype(int)
    score, chance = beat_align_over_chance(_swing(3600, 2.0), beats, variant, 60.0)
    assert score > 0.1 and abs(score - chance) < 0.03, (score, chance)


def test_fewer_than_two_beats_have_no_chance():
    score, chance = beat_align_over_chance(_swing(120, 2.0), [23], "fact", 60.0)
    assert score == pytest.approx(sequence_beat_align(_swing(120, 2.0), [23], "fact", 60.0)) and math.isnan(
        chance
    )


def test_conditioning_scores_are_each_dances_margin_beside_its_truths_on_the_same_beats():
    from skeleton_mamba.tasks.motion.metrics.beat_conditioning import (
        TARGET_FRACTION,
        conditioning_scores,
        format_conditioning,
    )

    truth = _swing(240, 2.0)  # stops every 15 frames, on beats 8, 23, ...
    late = np.roll(truth, 7, axis=0)  # half a beat late: below chance
    short = truth[:200]  # the dance ends before the truth: both are scored on their first 200 frames
    beats = np.arange(8, 240, 15)
    scores = conditioning_scores([truth, late, short], [truth, truth, truth], [beats] * 3, 60.0)

    def margin(motion: np.ndarray, frames: np.ndarray) -> float:
        score, chance = beat_align_over_chance(motion, frames, "bailando", 60.0)
        return score - chance

    expected = [margin(truth, beats), margin(late, beats), margin(short, beats[beats < 200])]
    assert scores["per_sequence"] == pytest.approx(expected)
    assert scores["truth_per_sequence"] == pytest.approx(
        [margin(truth, beats), margin(truth, beats), margin(truth[:200], beats[beats < 200])]
    )
    assert expected[1] < 0 < expected[0]
    assert scores["margin"] == pytest.approx(np.mean(expected))
    assert scores["reached"] is bool(scores["margin"] >= TARGET_FRACTION * scores["truth_margin"])
    assert conditioning_scores([truth], [truth], [beats], 60.0)["reached"] is True
    assert conditioning_scores([late], [truth], [beats], 60.0)["reached"] is False
    text = format_conditioning(conditioning_scores([late], [truth], [beats], 60.0))
    assert f"dance {margin(late, beats):+.3f}, ground truth {margin(truth, beats):+.3f}" in text
    assert "NOT reached: beat margin over chance >= 0.5 x the ground truth's" in text
