"""The normalised Gaussian low-pass over time (tasks/motion/body/temporal_filter.py) against independent
sums."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.motion.body.temporal_filter import gaussian_kernel, smooth_over_time


def _reference(x: np.ndarray, sigma: float, valid: np.ndarray, truncate: float = 3.0) -> np.ndarray:
    """Frame by frame: sum_k w_k m_{t+k} x_{t+k} / sum_k w_k m_{t+k}, padded frames kept as they are."""
    radius = max(1, math.ceil(truncate * sigma))
    out = x.copy()
    for t in range(x.shape[0]):
        if not valid[t]:
            continue
        num, den = np.zeros(x.shape[1:]), 0.0
        for k in range(-radius, radius + 1):
            if 0 <= t + k < x.shape[0] and valid[t + k]:
                w = math.exp(-0.5 * (k / sigma) ** 2)
                num += w * x[t + k]
                den += w
        out[t] = num / den
    return out


@pytest.mark.parametrize("sigma", [0.7, 2.0, 3.5])
def test_equals_the_frame_by_frame_sum_with_ends_and_padding(sigma):
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(3, 40, 4, 2, generator=gen, dtype=torch.float64)
    lengths = [40, 29, 7]
    mask = torch.arange(40)[None] < torch.tensor(lengths)[:, None]
    out = smooth_over_time(x, sigma, mask)
    for b in range(3):
        ref = _reference(x[b].numpy(), sigma, mask[b].numpy())
        np.testing.assert_allclose(out[b].numpy(), ref, rtol=1e-12, atol=1e-12)


def test_sinusoid_is_attenuated_by_the_gaussian_response():
    """Away from the ends a sinusoid of f cycles per frame comes out scaled by exp(-2 pi^2 sigma^2 f^2)."""
    sigma, frames = 2.0, 400
    t = torch.arange(frames, dtype=torch.float64)
    for hz in (1.0, 2.0, 5.0):
        f = hz / 30.0
        x = torch.sin(2 * math.pi * f * t)[None, :, None]
        y = smooth_over_time(x, sigma, truncate=6.0)[0, 50:-50, 0]
        gain = float((y * x[0, 50:-50, 0]).sum() / x[0, 50:-50, 0].square().sum())
        assert gain == pytest.approx(math.exp(-2 * math.pi**2 * sigma**2 * f**2), abs=2e-3), hz


def test_padding_never_leaks_and_constants_stay_constant():
    gen = torch.Generator().manual_seed(1)
    x = torch.randn(1, 30, 5, generator=gen)
    mask = torch.arange(30)[None] < 20
    y = x.clone()
    y[:, 20:] = 1e6  # other values in the padding
    a, b = smooth_over_time(x, 2.0, mask), smooth_over_time(y, 2.0, mask)
    torch.testing.assert_close(a[:, :20], b[:, :20])
    torch.testing.assert_close(b[:, 20:], y[:, 20:])  # padded frames returned unchanged
    const = torch.full((2, 25, 3), 0.37)
    torch.testing.assert_close(smooth_over_time(const, 3.0), const)


def test_kernel_and_bad_sigma():
    k = gaussian_kernel(1.0)
    assert k.numel() == 7 and float(k[3]) == 1.0 and float(k[0]) == pytest.approx(math.exp(-4.5))
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="sigma"):
            smooth_over_time(torch.zeros(1, 5, 2), bad)
