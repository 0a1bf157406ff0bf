"""Motion amplitude, jitter and energy above 6 Hz (tasks/motion/metrics/dynamics.py) against hand
computations."""

from __future__ import annotations

import math

import pytest
import torch

from skeleton_mamba.tasks.motion.metrics.dynamics import (
    dynamics_checks,
    dynamics_ratios,
    high_frequency_energy,
    motion_amplitude,
    motion_jitter,
)

FPS = 30.0


def _sine_motion(amplitude: float, hz: float, seconds: float = 4.0, joints: int = 5) -> torch.Tensor:
    """(T, J, 3) float64: the root walks along z at 1 m/s; joint 1 swings A sin(2 pi f t) along x about the
    root, the other joints stand still relative to it (mean over the 4 non-root joints: A / sqrt 2 / 4)."""
    t = torch.arange(int(seconds * FPS), dtype=torch.float64) / FPS
    motion = torch.zeros(t.shape[0], joints, 3, dtype=torch.float64)
    motion[:, :, 1] = torch.linspace(0.0, 1.0, joints, dtype=torch.float64)  # a column of joints, y-up
    motion[:, :, 2] += t[:, None]  # every joint carried along by the root
    motion[:, 1, 0] += amplitude * torch.sin(2 * math.pi * hz * t)
    return motion


def test_amplitude_of_a_sine_swing_and_a_still_pose():
    a, hz = 0.3, 1.5  # 4 s at 1.5 Hz: 6 whole periods, so the population variance of A sin is A^2 / 2
    motion = _sine_motion(a, hz)
    assert motion_amplitude(motion).item() == pytest.approx(a / math.sqrt(2) / 4, rel=1e-9)
    still = motion[:1].expand(20, -1, -1)
    assert motion_amplitude(still).item() == 0.0
    assert motion_jitter(still, FPS).item() == 0.0


def test_jitter_of_a_sine_swing_is_its_discrete_acceleration():
    """Second difference of A sin(w n / fps): -4 sin^2(w / 2 fps) A sin(.) (exact); the root's constant
    velocity adds nothing; mean |.| over the interior frames and all 5 joints (4 do not accelerate)."""
    a, hz = 0.3, 1.5
    motion = _sine_motion(a, hz)
    w = 2 * math.pi * hz
    n = torch.arange(1, motion.shape[0] - 1, dtype=torch.float64)
    per_frame = 4 * math.sin(w / (2 * FPS)) ** 2 * a * torch.sin(w * n / FPS).abs() * FPS**2
    assert motion_jitter(motion, FPS).item() == pytest.approx(per_frame.mean().item() / 5, rel=1e-9)
    # and close to the continuous A w^2 * mean|sin| = A w^2 2 / pi
    assert motion_jitter(motion, FPS).item() == pytest.approx(a * w**2 * 2 / math.pi / 5, rel=0.02)


def test_added_white_noise_raises_jitter_not_amplitude():
    motion = _sine_motion(0.3, 1.5)
    noisy = motion + 0.01 * torch.randn(
        motion.shape, generator=torch.Generator().manual_seed(0), dtype=torch.float64
    )
    ratios = dynamics_ratios(noisy, motion, FPS)
    # noise of std 1 cm per axis: second differences of std sqrt(6) cm per axis, |.| of a 3-d Gaussian
    # of that std has mean sqrt(8 / pi) sqrt(6) cm, times fps^2 = 900: about 44 m/s^2 against 3.4 m/s^2
    expected_noise = math.sqrt(8 / math.pi) * math.sqrt(6) * 0.01 * FPS**2
    assert motion_jitter(noisy, FPS).item() == pytest.approx(expected_noise, rel=0.1)
    assert ratios["jitter_ratio"] > 10
    # root-relative spread: the noise of joint and root (variance 2 n^2 per axis, 3 axes) adds to each joint's
    # variance: joint 1 sqrt(A^2 / 2 + 6 n^2), the 3 still joints sqrt(6 n^2), mean over the 4
    n, a = 0.01, 0.3
    spread = (math.sqrt(a**2 / 2 + 6 * n**2) + 3 * math.sqrt(6 * n**2)) / 4
    assert ratios["amplitude_ratio"] == pytest.approx(spread / (a / math.sqrt(2) / 4), rel=0.05)
    assert ratios["high_frequency_ratio"] > 10  # white noise spreads over every frequency; the swing has none
    assert dynamics_checks(ratios) == {
        "amplitude ratio >= 0.7": True,
        "jitter ratio <= 1.5": False,
        "energy above 6 Hz within 2x of the ground truth's": False,
    }


def test_energy_above_6_hz_is_the_mean_square_velocity_of_the_fast_swing_alone():
    """A 2 Hz swing plus a 10 Hz one; 121 frames give 120 velocities, so both fall on DFT bins (0.25 Hz
    apart) and nothing leaks. The sampled velocity of A sin(w t) is the tone 2 A fps sin(w / 2 fps)
    cos(w (n + 1/2) / fps), of mean square (2 A fps sin(w / 2 fps))^2 / 2; only joint 1 of 5 moves."""
    t = torch.arange(121, dtype=torch.float64) / FPS
    motion = torch.zeros(121, 5, 3, dtype=torch.float64)
    slow, fast = 0.3 * torch.sin(2 * math.pi * 2.0 * t), 0.01 * torch.sin(2 * math.pi * 10.0 * t)
    motion[:, 1, 0] = slow
    motion[:, 1, 2] = fast
    tone = 2 * 0.01 * FPS * math.sin(2 * math.pi * 10.0 / (2 * FPS))
    assert high_frequency_energy(motion, FPS).item() == pytest.approx(tone**2 / 2 / 5, rel=1e-9)
    motion[:, 1, 2] = 0.0
    assert high_frequency_energy(motion, FPS).item() == pytest.approx(0.0, abs=1e-20)
    # the cutoff moves the band: below 2 Hz the slow swing counts as well
    slow_tone = 2 * 0.3 * FPS * math.sin(2 * math.pi * 2.0 / (2 * FPS))
    assert high_frequency_energy(motion, FPS, cutoff_hz=1.0).item() == pytest.approx(
        slow_tone**2 / 2 / 5, rel=1e-9
    )


def test_a_smoothed_copy_loses_its_energy_above_6_hz():
    """A 1.5 Hz swing with a 9 Hz accent; averaging each frame with its neighbours (a 3-tap box filter,
    gain (1 + 2 cos(2 pi f / fps)) / 3: 0.97 at 1.5 Hz, 0.13 at 9 Hz) keeps the swing and flattens the
    accent below half the truth's energy: the check fails although amplitude and jitter look fine."""
    t = torch.arange(241, dtype=torch.float64) / FPS
    motion = torch.zeros(241, 3, 3, dtype=torch.float64)
    motion[:, 1, 0] = 0.3 * torch.sin(2 * math.pi * 1.5 * t) + 0.01 * torch.sin(2 * math.pi * 9.0 * t)
    smooth = motion.clone()
    smooth[1:-1] = (motion[:-2] + motion[1:-1] + motion[2:]) / 3
    ratios = dynamics_ratios(smooth, motion, FPS)
    gain = (1 + 2 * math.cos(2 * math.pi * 9.0 / FPS)) / 3
    assert ratios["high_frequency_ratio"] == pytest.approx(gain**2, rel=0.1)  # the two end frames aside
    assert ratios["amplitude_ratio"] > 0.7 and ratios["jitter_ratio"] < 1.5
    assert dynamics_checks(ratios)["energy above 6 Hz within 2x of the ground truth's"] is False


def test_a_timid_copy_has_the_amplitude_ratio_of_its_scale():
    motion = _sine_motion(0.3, 1.5)
    timid = motion.clone()
    timid[:, 1, 0] = motion[:, 1, 0] * 0.5  # the swing halved: amplitude and acceleration halved
    ratios = dynamics_ratios(timid, motion, FPS)
    assert ratios["amplitude_ratio"] == pytest.approx(0.5, rel=1e-9)
    assert ratios["jitter_ratio"] == pytest.approx(0.5, rel=1e-9)
    assert ratios["high_frequency_ratio"] == pytest.approx(0.25, rel=1e-9)  # power: the square of 0.5
    assert dynamics_checks(ratios) == {
        "amplitude ratio >= 0.7": False,
        "jitter ratio <= 1.5": True,
        "energy above 6 Hz within 2x of the ground truth's": False,
    }


def test_a_still_reference_gives_nan_ratios_that_reach_no_target():
    still = torch.zeros(10, 3, 3)
    ratios = dynamics_ratios(still, still, FPS)
    assert all(math.isnan(value) for value in ratios.values()) and len(ratios) == 3
    assert not any(dynamics_checks(ratios).values())


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="T >= 3"):
        motion_jitter(torch.zeros(2, 4, 3), FPS)
    with pytest.raises(ValueError, match="J >= 2"):
        motion_amplitude(torch.zeros(5, 1, 3))
    with pytest.raises(ValueError, match="T >= 3"):
        high_frequency_energy(torch.zeros(2, 4, 3), FPS)
