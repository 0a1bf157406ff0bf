"""How much a motion moves, and how much it trembles: amplitude and jitter, and their ratios to a reference.

Two scores that a timid or a trembling dance fails even when its poses are plausible and its mean error is
small (a figure held at the mean pose has low MPJPE and no foot skating):

- :func:`motion_amplitude`: the root-relative joint positions' spread over the window, per joint the root
  mean square distance from its mean position ``sqrt(sum_xyz var_t(p_j - p_root))``, mean over the
  non-root joints (metres). A still pose scores 0; a joint swinging ``A sin(w t)`` along one axis
  ``A / sqrt 2``.
- :func:`motion_jitter`: the mean joint acceleration magnitude, ``|p_{t+1} - 2 p_t + p_{t-1}| fps^2``
  (the central second difference of the world positions), mean over the interior frames and every joint
  (m/s^2). Frame-to-frame noise of std ``n`` adds about ``sqrt 6 n fps^2`` to it, smooth motion little.
- :func:`high_frequency_energy`: the joint velocities' mean power above :data:`HIGH_FREQUENCY_HZ` (6 Hz),
  from their spectrum over time (m^2/s^2). A smoothed dance that lost the truth's sharp accents has less of
  it than the truth, a trembling one more: the check that a cure for trembling did not flatten real motion.

:func:`dynamics_ratios` states both as ratios to a reference motion (the ground truth): a dance that moves as
much as its truth has amplitude ratio 1, one that trembles has a jitter ratio above 1. The demos hold their
dances to :data:`AMPLITUDE_RATIO_TARGET`, :data:`JITTER_RATIO_TARGET` and, for the energy above 6 Hz,
:data:`HIGH_FREQUENCY_RATIO_RANGE` (:func:`dynamics_checks`).
"""

from __future__ import annotations

import torch

__all__ = [
    "AMPLITUDE_RATIO_TARGET",
    "DYNAMICS_METRICS",
    "HIGH_FREQUENCY_HZ",
    "HIGH_FREQUENCY_RATIO_RANGE",
    "JITTER_RATIO_TARGET",
    "dynamics_checks",
    "dynamics_ratios",
    "high_frequency_energy",
    "motion_amplitude",
    "motion_jitter",
]

AMPLITUDE_RATIO_TARGET = 0.7  # at least 70 % of the reference's spread: not a timid dance
JITTER_RATIO_TARGET = 1.5  # at most 1.5 times the reference's acceleration: not a trembling dance
HIGH_FREQUENCY_HZ = 6.0  # above the beat rates of dance (1-3 Hz) and their first harmonics
HIGH_FREQUENCY_RATIO_RANGE = (0.5, 2.0)  # within 2x of the reference's energy above 6 Hz, either way
DYNAMICS_METRICS = {  # key -> printed name
    "amplitude_ratio": "motion amplitude / ground truth's",
    "jitter_ratio": "jitter (acceleration) / ground truth's",
    "high_frequency_ratio": f"energy above {HIGH_FREQUENCY_HZ:g} Hz / ground truth's",
}


def motion_amplitude(joints: torch.Tensor, root: int = 0) -> torch.Tensor:
    """Mean per-joint root-relative spread (metres, scalar) of joints (T, J, 3) (population variance).

    Examples:
        >>> import torch
        >>> joints = torch.zeros(4, 2, 3)
        >>> joints[:, 1, 0] = torch.tensor([0.1, -0.1, 0.1, -0.1])  # joint 1 swings 10 cm about the root
        >>> round(float(motion_amplitude(joints)), 4)
        0.1
    """
    if joints.ndim != 3 or joints.shape[-1] != 3 or joints.shape[1] < 2:
        raise ValueError(f"joints must be (T, J >= 2, 3), got {tuple(joints.shape)}")
    relative = joints - joints[:, root : root + 1]
    spread = relative.var(dim=0, unbiased=False).sum(dim=-1).sqrt()  # (J,)
    keep = torch.ones(joints.shape[1], dtype=torch.bool, device=joints.device)
    keep[root] = False
    return spread[keep].mean()


def motion_jitter(joints: torch.Tensor, fps: float) -> torch.Tensor:
    """Mean joint acceleration magnitude (m/s^2, scalar) of joints (T >= 3, J, 3) at ``fps``.

    Examples:
        >>> import torch
        >>> t = torch.arange(6.0)
        >>> joints = torch.zeros(6, 2, 3)
        >>> joints[..., 0] = (0.01 * t**2)[:, None]  # 0.02 m per frame^2 at 10 fps: 2 m/s^2
        >>> round(float(motion_jitter(joints, fps=10.0)), 4)
        2.0
    """
    if joints.ndim != 3 or joints.shape[-1] != 3 or joints.shape[0] < 3:
        raise ValueError(f"joints must be (T >= 3, J, 3), got {tuple(joints.shape)}")
    accel = (joints[2:] - 2 * joints[1:-1] + joints[:-2]) * fps**2
    return accel.norm(dim=-1).mean()


def high_frequency_energy(
    joints: torch.Tensor, fps: float, cutoff_hz: float = HIGH_FREQUENCY_HZ
) -> torch.Tensor:
    """Mean power (m^2/s^2, scalar) of the joint velocities of joints (T >= 3, J, 3) above ``cutoff_hz``.

    The velocities ``v_t = (p_{t+1} - p_t) fps`` (T - 1 frames) are taken to the frequency domain per joint
    and axis (``rfft`` over time); by Parseval's theorem the power of the bins above the cutoff,
    ``sum_{f_k > cutoff} w_k |V_k|^2 / N^2`` (``w_k`` = 2 for the bins that stand for two of the full
    spectrum, 1 for the Nyquist bin), is the mean square of the velocity's part above the cutoff. Summed
    over the axes, mean over the joints.

    Examples:
        >>> import torch
        >>> t = torch.arange(60.0) / 30  # 2 s at 30 fps
        >>> slow, fast = torch.zeros(60, 2, 3), torch.zeros(60, 2, 3)
        >>> slow[..., 0] = torch.sin(2 * torch.pi * 1 * t)[:, None]  # 1 Hz
        >>> fast[..., 0] = torch.sin(2 * torch.pi * 10 * t)[:, None]  # 10 Hz
        >>> round(float(high_frequency_energy(slow, fps=30.0)), 3)
        0.0
        >>> bool(high_frequency_energy(fast, fps=30.0) > 1)
        True
    """
    if joints.ndim != 3 or joints.shape[-1] != 3 or joints.shape[0] < 3:
        raise ValueError(f"joints must be (T >= 3, J, 3), got {tuple(joints.shape)}")
    if not 0 < cutoff_hz:
        raise ValueError(f"cutoff_hz must be > 0, got {cutoff_hz}")
    velocity = (joints[1:] - joints[:-1]) * fps  # (N, J, 3)
    n = velocity.shape[0]
    spectrum = torch.fft.rfft(velocity, dim=0).abs().pow(2)  # (n // 2 + 1, J, 3)
    freqs = torch.fft.rfftfreq(n, d=1.0 / fps).to(joints.device)
    weight = torch.full_like(freqs, 2.0)
    weight[0] = 1.0
    if n % 2 == 0:
        weight[-1] = 1.0  # the Nyquist bin stands for itself alone
    weight = weight * (freqs > cutoff_hz)
    power = (spectrum * weight[:, None, None].to(spectrum.dtype)).sum(0) / n**2  # (J, 3)
    return power.sum(-1).mean()


def _ratio(value: torch.Tensor, reference: torch.Tensor) -> float:
    """value / reference; NaN when the reference is 0 (a still reference has no scale to compare with)."""
    reference = float(reference)
    return float(value) / reference if reference > 0 else float("nan")


def dynamics_ratios(joints: torch.Tensor, reference: torch.Tensor, fps: float) -> dict[str, float]:
    """``amplitude_ratio``, ``jitter_ratio`` and ``high_frequency_ratio`` of joints (T, J, 3) to a reference
    motion (T', J, 3).

    Examples:
        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> truth = torch.randn(30, 22, 3)
        >>> {k: round(v, 4) for k, v in dynamics_ratios(2 * truth, truth, fps=30.0).items()}
        {'amplitude_ratio': 2.0, 'jitter_ratio': 2.0, 'high_frequency_ratio': 4.0}
    """
    joints, reference = joints.double(), reference.double()
    return {
        "amplitude_ratio": _ratio(motion_amplitude(joints), motion_amplitude(reference)),
        "jitter_ratio": _ratio(motion_jitter(joints, fps), motion_jitter(reference, fps)),
        "high_frequency_ratio": _ratio(
            high_frequency_energy(joints, fps), high_frequency_energy(reference, fps)
        ),
    }


def dynamics_checks(ratios: dict[str, float]) -> dict[str, bool]:
    """Whether :func:`dynamics_ratios` reach the targets (a NaN ratio reaches none).

    Examples:
        >>> as_truth = {"amplitude_ratio": 1.0, "jitter_ratio": 1.0, "high_frequency_ratio": 1.0}
        >>> all(dynamics_checks(as_truth).values())
        True
        >>> all(dynamics_checks({**as_truth, "amplitude_ratio": 0.2}).values())  # a timid dance
        False
    """
    low, high = HIGH_FREQUENCY_RATIO_RANGE
    return {
        f"amplitude ratio >= {AMPLITUDE_RATIO_TARGET}": ratios["amplitude_ratio"] >= AMPLITUDE_RATIO_TARGET,
        f"jitter ratio <= {JITTER_RATIO_TARGET}": ratios["jitter_ratio"] <= JITTER_RATIO_TARGET,
        f"energy above {HIGH_FREQUENCY_HZ:g} Hz within {high:g}x of the ground truth's": (
            low <= ratios["high_frequency_ratio"] <= high
        ),
    }
