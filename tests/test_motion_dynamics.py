"""Motion amplitude and jitter (tasks/motion/metrics/dynamics.py) against hand computations."""

from __future__ import annotations

import math

import pytest
import torch

from skeleton_mamba.tasks.motion.metrics.dynamics import (
    dynamics_checks,
    dynamics_ratios,
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
    assert dynamics_checks(ratios) == {"amplitude ratio >= 0.7": True, "jitter ratio <= 1.5": False}


def test_a_timid_copy_has_the_amplitude_ratio_of_its_scale():
    motion = _sine_motion(0.3, 1.5)
    timid = motion.clone()
    timid[:, 1, 0] = motion[:, 1, 0] * 0.5  # the swing halved: amplitude and acceleration halved
    ratios = dynamics_ratios(timid, motion, FPS)
    assert ratios["amplitude_ratio"] == pytest.approx(0.5, rel=1e-9)
    assert ratios["jitter_ratio"] == pytest.approx(0.5, rel=1e-9)
    assert dynamics_checks(ratios) == {"amplitude ratio >= 0.7": False, "jitter ratio <= 1.5": True}


def test_a_still_reference_gives_nan_ratios_that_reach_no_target():
    still = torch.zeros(10, 3, 3)
    ratios = dynamics_ratios(still, still, FPS)
    assert math.isnan(ratios["amplitude_ratio"]) and math.isnan(ratios["jitter_ratio"])
    assert not any(dynamics_checks(ratios).values())


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="T >= 3"):
        motion_jitter(torch.zeros(2, 4, 3), FPS)
    with pytest.raises(ValueError, match="J >= 2"):
        motion_amplitude(torch.zeros(5, 1, 3))
