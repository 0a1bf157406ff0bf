"""A Gaussian-process prior over time for the x0 preconditioning: the skip connection as a Wiener filter.

:class:`~.parameterisation.SkipX0` returns ``x0_hat = mu + c_skip y_t + c_out F`` (``y_t = x_t - a mu``), and
its ``F = 0`` output is the posterior mean of x0 under a prior that draws every frame on its own (per
channel mean ``mu`` and variance ``sigma^2``). Where the network has learned little, that is what a sampler
returns: white noise of the data's variance about the mean, as strong at 9 Hz as at 1 Hz, the trembling of
a briefly trained text-to-motion model (its skip connection also passes x_t's white noise on at every t).

Here the prior is a stationary Gaussian process per channel instead: over the L frames of a sequence its
covariance is diagonal in the orthonormal DCT-II basis ``D`` (L x L, row k the frequency ``k / (2 L)``
cycles per frame) with the training data's power ``Q_k = P(k / (2 L))`` at each frequency. With
``Y = D y_t`` and ``G = D F`` (per channel, over the sequence's frames)::

    x0_hat = mu + D^T [ a Q / (a^2 Q + s^2) Y  +  s sqrt(Q / (a^2 Q + s^2)) G ]

The first term is the exact posterior mean of x0 given x_t under that prior (the Wiener filter: each
frequency kept in proportion to its signal-to-noise ratio), the second scales the network's output by the
posterior standard deviation of each frequency, so F's target stays white with unit variance. With a flat
spectrum ``Q = sigma^2`` both are SkipX0's ``a sigma^2 / d`` and ``sigma s / sqrt(d)``. An untrained network
(``F = 0``) then samples smooth motion with the data's per-channel spectrum, and no output of the network
reaches a frequency beyond the power the data has there. The network's input is SkipX0's
(``y_t / sqrt(a^2 sigma^2 + s^2)``).

The spectrum is Welch's estimate on Hann-windowed stretches of the training sequences about the data's
mean (:func:`power_spectrum`; the power at frequency 0 holds the sequences' own offsets), read at a
sequence's own frequencies by linear interpolation (:func:`spectrum_at`): for a stationary process the DCT
coefficient k has about the power at ``k / (2 L)``. The DCT extends a sequence evenly at both ends (the
process mirrored there), so the prior puts no jump at the ends.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from skeleton_mamba.tasks.training.diffusion.parameterisation import SkipX0

__all__ = ["TemporalPriorSkipX0", "dct_bases", "power_spectrum", "spectrum_at"]


def dct_bases(lengths: torch.Tensor, frames: int) -> torch.Tensor:
    """Each sequence's orthonormal DCT-II matrix (B, T, T) for lengths (B,) (1 <= L_b <= T = ``frames``):
    ``D[k, n] = c_k sqrt(2 / L) cos(pi (n + 1/2) k / L)`` (``c_0 = 1 / sqrt 2``, ``c_k = 1`` otherwise) for
    ``k, n < L``, zero elsewhere, so ``D D^T`` is the identity on the first L frames."""
    length = lengths.to(torch.float64)[:, None, None]  # (B, 1, 1)
    index = torch.arange(frames, dtype=torch.float64, device=lengths.device)
    k, n = index[None, :, None], index[None, None, :]
    basis = torch.cos(math.pi * (n + 0.5) * k / length) * (2.0 / length).sqrt()
    basis = torch.where(k == 0, basis / math.sqrt(2.0), basis)
    return torch.where((k < length) & (n < length), basis, torch.zeros_like(basis))


def power_spectrum(sequences: Sequence[torch.Tensor], segment: int, mean: torch.Tensor) -> torch.Tensor:
    """Welch's estimate of the power spectral density (segment // 2 + 1, C) float32 of sequences (T_i, C)
    about ``mean`` (C,), at the frequencies ``j / segment`` cycles per frame, j = 0 .. segment // 2.

    Every ``segment``-frame stretch (hop ``segment // 4``) is weighted by a Hann window ``w`` and
    ``|rfft(w (x - mean))|^2 / sum(w^2)`` is averaged over them all: white noise of variance ``v`` has ``v``
    at every frequency. The window keeps the power of the slow swings out of the high frequencies (without
    it a stretch's two ends, joined, would add a jump's power there). A sequence of fewer frames (at least
    2) is one stretch, windowed over its own length and padded with zeros to ``segment`` (the same
    frequencies, a coarser resolution).

    Raises:
        ValueError: no sequence has 2 frames, or a value is NaN or inf.
    """
    if segment < 2:
        raise ValueError(f"segment must be >= 2 frames, got {segment}")
    hop = max(1, segment // 4)
    total, count = 0.0, 0
    for sequence in sequences:
        frames = sequence.shape[0]
        if frames < 2:
            continue
        x = sequence.double() - mean.double()
        if not torch.isfinite(x).all():
            raise ValueError("spectrum: the values contain NaN or inf")
        window = torch.hann_window(min(frames, segment), periodic=True, dtype=torch.float64)
        stretches = x.unfold(0, segment, hop) if frames >= segment else x.T[None]  # (S, C, <= segment)
        spectra = (
            torch.fft.rfft(stretches * window, n=segment, dim=-1).abs().pow(2)
        )  # (S, C, segment // 2 + 1)
        total = total + spectra.sum(0).T / window.square().sum()
        count += stretches.shape[0]
    if count == 0:
        raise ValueError("spectrum: no sequence has 2 frames")
    return (total / count).float()


def spectrum_at(spectrum: torch.Tensor, lengths: torch.Tensor, frames: int) -> torch.Tensor:
    """The power (B, T, C) at the frequencies ``k / (2 L_b)`` of each sequence's DCT (k < T = ``frames``),
    linearly interpolated from a spectrum (N + 1, C) at ``j / (2 N)``, j = 0 .. N (0 to the Nyquist
    frequency, :func:`power_spectrum`); rows ``k >= L_b`` hold the Nyquist power."""
    last = spectrum.shape[0] - 1
    index = torch.arange(frames, dtype=torch.float64, device=spectrum.device)
    position = (index[None, :] * last / lengths.to(torch.float64)[:, None]).clamp(max=last)  # (B, T)
    low = position.floor().long()
    high = (low + 1).clamp(max=last)
    weight = (position - low).to(spectrum.dtype)[..., None]
    return spectrum[low] * (1 - weight) + spectrum[high] * weight


class TemporalPriorSkipX0(SkipX0):
    """:class:`~.parameterisation.SkipX0` with the Gaussian-process prior over time above, for x (B, T, C).

    Args:
        num_steps: diffusion steps T (must match the model's :class:`GaussianDiffusion`).
        channels: C, the channels of a frame.
        segment: the frames of the stretches the spectrum is estimated on (:func:`power_spectrum`; its
            frequency resolution ``1 / segment`` cycles per frame).
        cosine_s: the offset s of the cosine schedule.
    """

    def __init__(self, num_steps: int = 1000, channels: int = 1, segment: int = 64, cosine_s: float = 0.008):
        super().__init__(num_steps, channels=(channels,), cosine_s=cosine_s)
        if segment < 2:
            raise ValueError(f"segment must be >= 2 frames, got {segment}")
        self.segment = segment
        # flat: SkipX0's white prior until the data's spectrum is set
        self.register_buffer("spectrum", torch.ones(segment // 2 + 1, channels))

    @torch.no_grad()
    def set_spectrum(self, spectrum: torch.Tensor, min_power: float = 1e-8) -> None:
        """The data's power spectrum (segment // 2 + 1, C) (:func:`power_spectrum`), floored at
        ``min_power``."""
        if spectrum.shape != self.spectrum.shape:
            expected = tuple(self.spectrum.shape)
            raise ValueError(f"spectrum of shape {tuple(spectrum.shape)}, expected {expected}")
        if not torch.isfinite(spectrum).all():
            raise ValueError("spectrum contains NaN or inf")
        self.spectrum.copy_(spectrum.clamp(min=min_power))

    def forward(
        self, x_t: torch.Tensor, out: torch.Tensor, t: torch.Tensor, mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        """x_t and F (B, T, C), t (B,) long, mask (B, T) bool valid frames (right padding; None: all) ->
        x0_hat (B, T, C). Padded frames get SkipX0's per-frame output."""
        a, s, mu, _, _ = self._scalings(x_t, t)
        frames = x_t.shape[1]
        lengths = (
            torch.full(x_t.shape[:1], frames, device=x_t.device) if mask is None else mask.sum(1).clamp(min=1)
        )  # (B,)
        basis = dct_bases(lengths, frames).to(x_t.dtype)  # (B, T, T)
        power = spectrum_at(self.spectrum.to(x_t.dtype), lengths, frames)  # (B, T, C): Q_k
        variance = a.square() * power + s.square()
        coefficients = a * power / variance * (basis @ (x_t - a * mu)) + s * (power / variance).sqrt() * (
            basis @ out
        )
        prior = mu + basis.transpose(1, 2) @ coefficients
        if mask is None:
            return prior
        return torch.where(mask[..., None], prior, super().forward(x_t, out, t))
