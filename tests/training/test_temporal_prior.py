"""The Gaussian-process prior over time of the x0 preconditioning (``diffusion/temporal_prior.py``): the DCT
bases against scipy's, the spectrum against scipy's Welch, the F = 0 output against the Gaussian posterior
mean computed by a linear solve, the network's scaling against the posterior covariance, SkipX0 as the
flat-spectrum case, padding, and samples of an untrained network that keep the data's band."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import fft as sp_fft
from scipy import signal

from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, sample
from skeleton_mamba.tasks.training.diffusion.parameterisation import SkipX0
from skeleton_mamba.tasks.training.diffusion.temporal_prior import (
    TemporalPriorSkipX0,
    dct_bases,
    power_spectrum,
    spectrum_at,
)

STEPS = 50


def _scipy_dct(length: int) -> np.ndarray:
    """The orthonormal DCT-II matrix (L, L) from scipy: column n is the transform of the n-th unit vector."""
    return sp_fft.dct(np.eye(length), type=2, norm="ortho", axis=0)


def test_dct_bases_are_scipys_orthonormal_dct_padded_with_zeros():
    bases = dct_bases(torch.tensor([5, 8, 1]), 8).numpy()
    for b, length in enumerate((5, 8, 1)):
        np.testing.assert_allclose(bases[b, :length, :length], _scipy_dct(length), atol=1e-12)
        assert (
            np.abs(bases[b, length:]).max(initial=0) == 0 and np.abs(bases[b, :, length:]).max(initial=0) == 0
        )
        np.testing.assert_allclose(
            bases[b] @ bases[b].T, np.diag([1.0] * length + [0.0] * (8 - length)), atol=1e-12
        )


def test_power_spectrum_is_welchs_two_sided_density():
    rng = np.random.default_rng(0)
    # AR(1) sequences (a low-pass spectrum), three channels; the last is shorter than a segment
    sequences = []
    for frames in (150, 97, 20):
        noise = rng.standard_normal((frames, 3))
        x = np.zeros_like(noise)
        for i in range(1, frames):
            x[i] = 0.8 * x[i - 1] + noise[i]
        sequences.append(x + np.array([1.0, -2.0, 0.5]))
    mean = np.array([0.9, -2.1, 0.4])
    segment, hop = 32, 8
    ours = power_spectrum([torch.from_numpy(s) for s in sequences], segment, torch.from_numpy(mean)).double()
    # scipy's one-sided densities (all bins but 0 and Nyquist doubled): each long sequence's Welch mean over
    # its stretches, the short one's periodogram over its own length zero-padded to the segment
    densities, counts = [], []
    for s in sequences[:2]:
        freqs, density = signal.welch(
            s - mean, fs=1.0, window="hann", nperseg=segment, noverlap=segment - hop, detrend=False, axis=0
        )
        densities.append(density)
        counts.append((s.shape[0] - segment) // hop + 1)
    _, short = signal.periodogram(
        sequences[2] - mean, fs=1.0, window="hann", nfft=segment, detrend=False, axis=0
    )
    densities.append(short)
    counts.append(1)
    expected = sum(c * d for c, d in zip(counts, densities, strict=True)) / sum(counts)
    expected[1:-1] /= 2
    np.testing.assert_allclose(freqs, np.arange(segment // 2 + 1) / segment)
    np.testing.assert_allclose(ours.numpy(), expected, rtol=1e-5)


def test_power_spectrum_of_white_noise_is_its_variance_and_refuses_bad_data():
    noise = torch.randn(20_000, 2, generator=torch.Generator().manual_seed(1), dtype=torch.float64) * 3.0
    spectrum = power_spectrum([noise], 64, torch.zeros(2))
    assert spectrum.shape == (33, 2)
    assert spectrum.mean().item() == pytest.approx(9.0, rel=0.05)
    with pytest.raises(ValueError, match="no sequence has 2 frames"):
        power_spectrum([noise[:1]], 64, torch.zeros(2))
    bad = noise.clone()
    bad[5, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        power_spectrum([bad], 64, torch.zeros(2))


def test_spectrum_at_interpolates_linearly_in_frequency():
    spectrum = torch.tensor([0.0, 10.0, 20.0, 30.0, 40.0])[:, None]  # at j / 8 cycles per frame, j = 0..4
    # an 8-frame DCT has frequencies k / 16, halfway between the grid's; rows past the length: Nyquist
    got = spectrum_at(spectrum, torch.tensor([8, 4]), 10)[..., 0]
    freqs = torch.arange(10) / 16
    np.testing.assert_allclose(got[0].numpy(), np.interp(freqs, np.arange(5) / 8, [0, 10, 20, 30, 40]))
    np.testing.assert_allclose(got[1, :4].numpy(), [0, 10, 20, 30])  # k / 8
    assert (got[1, 4:] == 40).all()


def _prior(channels: int = 3, segment: int = 16, seed: int = 0) -> TemporalPriorSkipX0:
    gen = torch.Generator().manual_seed(seed)
    prior = TemporalPriorSkipX0(STEPS, channels, segment=segment)
    prior.set_statistics(torch.randn(channels, generator=gen), 0.5 + torch.rand(channels, generator=gen))
    freqs = torch.arange(segment // 2 + 1) / segment
    spectrum = torch.exp(-((freqs[:, None] / 0.1) ** 2)) * (1 + torch.rand(1, channels, generator=gen)) + 1e-3
    prior.set_spectrum(spectrum)
    return prior


@pytest.mark.parametrize("t", [0, 7, 25, 49])
def test_zero_network_output_is_the_gaussian_posterior_mean_and_f_has_its_covariance(t):
    """Per channel, with C = D^T diag(Q) D (scipy's D, Q by np.interp): x0_hat(F = 0) must be
    ``mu + a C (a^2 C + s^2 I)^-1 (x_t - a mu)`` and the map F -> x0_hat the posterior covariance's square
    root ``J J^T = C - a^2 C (a^2 C + s^2 I)^-1 C``."""
    prior = _prior().double()
    length, channels = 11, 3
    x_t = torch.randn(1, length, channels, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    steps = torch.tensor([t])
    abar = GaussianDiffusion(STEPS).alphas_cumprod.double()[t]
    a, s = abar.sqrt().item(), (1 - abar).sqrt().item()
    mean, spectrum = prior.data_mean.numpy(), prior.spectrum.numpy()
    basis = _scipy_dct(length)
    grid = np.arange(spectrum.shape[0]) / (2 * (spectrum.shape[0] - 1))
    out = prior(x_t, torch.zeros_like(x_t), steps)[0].numpy()
    # the Jacobian of x0_hat in F: column (n, c) is the output for F = the unit vector at frame n, channel c
    units = torch.eye(length * channels, dtype=torch.float64).reshape(-1, length, channels)
    columns = prior(x_t.expand(len(units), -1, -1), units, steps.expand(len(units))) - prior(
        x_t, torch.zeros_like(x_t), steps
    )
    jacobian = columns.reshape(length, channels, length, channels).permute(2, 3, 0, 1).numpy()
    for c in range(channels):
        power = np.interp(np.arange(length) / (2 * length), grid, spectrum[:, c])
        cov = basis.T @ np.diag(power) @ basis
        gain = a * cov @ np.linalg.inv(a * a * cov + s * s * np.eye(length))
        expected = mean[c] + gain @ (x_t[0, :, c].numpy() - a * mean[c])
        np.testing.assert_allclose(out[:, c], expected, rtol=1e-6, atol=1e-7)  # a, s: float32 buffers
        j = jacobian[:, c, :, c]
        np.testing.assert_allclose(j @ j.T, cov - a * gain @ cov, rtol=1e-5, atol=1e-8)
        assert np.abs(np.delete(jacobian[:, c], c, axis=2)).max() == 0  # channels stay apart


def test_a_flat_spectrum_is_skip_x0_and_padded_frames_are_skip_x0s():
    gen = torch.Generator().manual_seed(3)
    mean, std = torch.randn(4, generator=gen), 0.5 + torch.rand(4, generator=gen)
    skip = SkipX0(STEPS, channels=(4,))
    skip.set_statistics(mean, std)
    prior = TemporalPriorSkipX0(STEPS, 4, segment=8)
    prior.set_statistics(mean, std)
    prior.set_spectrum(std.square().expand(5, 4))
    x_t, out = torch.randn(3, 12, 4, generator=gen), torch.randn(3, 12, 4, generator=gen)
    t = torch.tensor([0, 20, 49])
    mask = torch.arange(12)[None] < torch.tensor([12, 7, 3])[:, None]
    torch.testing.assert_close(prior(x_t, out, t, mask), skip(x_t, out, t), atol=1e-5, rtol=1e-5)


def test_a_padded_sequence_is_the_sequence_alone():
    prior = _prior(seed=4)
    gen = torch.Generator().manual_seed(5)
    x_t, out = torch.randn(2, 20, 3, generator=gen), torch.randn(2, 20, 3, generator=gen)
    t = torch.tensor([10, 30])
    mask = torch.arange(20)[None] < torch.tensor([20, 13])[:, None]
    both = prior(x_t, out, t, mask)
    alone = prior(x_t[1:, :13], out[1:, :13], t[1:])
    torch.testing.assert_close(both[1:, :13], alone, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(both[:1], prior(x_t[:1], out[:1], t[:1]), atol=1e-6, rtol=1e-6)
    skip = SkipX0.forward(prior, x_t, out, t)  # SkipX0's per-frame output past the length
    torch.testing.assert_close(both[1, 13:], skip[1, 13:])


def test_set_spectrum_refuses_a_wrong_shape_or_nan():
    prior = TemporalPriorSkipX0(STEPS, 3, segment=16)
    with pytest.raises(ValueError, match=r"expected \(9, 3\)"):
        prior.set_spectrum(torch.ones(8, 3))
    with pytest.raises(ValueError, match="NaN"):
        prior.set_spectrum(torch.full((9, 3), float("nan")))
    with pytest.raises(ValueError, match="segment"):
        TemporalPriorSkipX0(STEPS, 3, segment=1)


def _band_fraction(x: torch.Tensor, cutoff: float) -> float:
    """Fraction of the power (about each channel's mean) at DCT frequencies above ``cutoff`` cycles/frame."""
    coefficients = torch.einsum(
        "kn,bnc->bkc", dct_bases(torch.tensor([x.shape[1]]), x.shape[1])[0], x.double()
    )
    freqs = torch.arange(x.shape[1]) / (2 * x.shape[1])
    power = coefficients[:, 1:].square()
    return float(power[:, freqs[1:] > cutoff].sum() / power.sum())


def test_an_untrained_network_samples_the_datas_band_not_white_noise():
    """With F = 0 DDIM returns samples of the prior: with a spectrum below 0.1 cycles per frame, almost no
    power above 0.15 (SkipX0's white prior: most of it), and about the prior's variance."""
    torch.manual_seed(0)
    diffusion = GaussianDiffusion(STEPS)
    prior = TemporalPriorSkipX0(STEPS, 4, segment=32)
    freqs = torch.arange(17) / 32
    prior.set_spectrum(torch.where(freqs < 0.1, 2.0, 1e-6)[:, None].expand(17, 4))
    white = SkipX0(STEPS, channels=(4,))

    def sample_with(skip) -> torch.Tensor:
        def denoiser(x_t, t, cond):
            return skip(x_t, torch.zeros_like(x_t), t)

        generator = torch.Generator().manual_seed(1)
        return sample(diffusion, denoiser, (16, 64, 4), sampler="ddim", sampling_steps=25, eta=0.0,
                      generator=generator)  # fmt: skip

    smooth, rough = sample_with(prior), sample_with(white)
    assert _band_fraction(smooth, 0.15) < 1e-3 and _band_fraction(rough, 0.15) > 0.5
    expected = float(spectrum_at(prior.spectrum, torch.tensor([64]), 64).mean())  # the prior's variance
    assert smooth.var().item() == pytest.approx(expected, rel=0.3)
