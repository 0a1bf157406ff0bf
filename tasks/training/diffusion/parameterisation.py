"""The x0 denoisers' preconditioning: scaled input, and x0 as a skip connection from x_t plus a correction.

A denoiser that must output x0 directly has to rebuild the whole clean signal at every t: at small t, where
``x_t`` already *is* x0 up to a little noise, a small network trained for a few hundred steps does that far
worse than returning ``x_t`` (the demo's EMM, 200 Adam steps on two 48-frame windows with the
reconstruction loss alone: x0 MSE 0.013 at t = 1 against 0.0018 for ``x_t``), and at large t it starts
far from the data mean. With the data's per-channel mean ``mu`` and standard deviation ``sigma``
(``0`` and ``1`` for standardised features), ``a = sqrt(alpha_bar_t)``, ``s = sqrt(1 - alpha_bar_t)`` and
``d = a^2 sigma^2 + s^2`` (the variance of ``y_t = x_t - a mu``), the network ``F`` sees ``y_t / sqrt(d)``
(unit variance) and the denoiser returns::

    x0_hat = mu + (a sigma^2 / d) y_t + (sigma s / sqrt(d)) F

the preconditioning of [EDM] (Table 1: ``c_in``, ``c_skip``, ``c_out`` with
``sigma_data`` per channel) in variance-preserving form about the data mean. With ``mu = 0, sigma = 1`` it is
``a x_t + s F``, the v-prediction of [v-pred] (``F = -v``). The optimal linear estimate
of x0 is the ``F = 0`` output, so an untrained network already returns the data mean at large t and
``x_t`` at small t. The denoiser still returns x0: the x0 losses ([EgoMusic] supp. Eqs. 26-29), guidance
and the samplers are unchanged.
"""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba.tasks.training.diffusion.schedule import NoiseSchedule

__all__ = ["SkipX0"]


class SkipX0(nn.Module):
    """The scalings above for the cosine schedule, with the data statistics as buffers.

    Args:
        num_steps: diffusion steps T (must match the model's :class:`GaussianDiffusion`).
        channels: the shape of one data frame, e.g. ``(24, 10)`` (the statistics' shape); ``None``: scalar
            statistics ``mu = 0``, ``sigma = 1`` (standardised data), kept out of checkpoints.
        cosine_s: the offset s of the cosine schedule.
    """

    def __init__(
        self, num_steps: int = 1000, channels: tuple[int, ...] | None = None, cosine_s: float = 0.008
    ):
        super().__init__()
        abar = NoiseSchedule.cosine(num_steps, cosine_s).alphas_cumprod
        self.num_steps = num_steps
        self.register_buffer("a", abar.sqrt().float(), persistent=False)
        self.register_buffer("s", (1.0 - abar).sqrt().float(), persistent=False)
        shape = channels or ()
        persistent = channels is not None
        self.register_buffer("data_mean", torch.zeros(shape), persistent=persistent)
        self.register_buffer("data_std", torch.ones(shape), persistent=persistent)

    @torch.no_grad()
    def set_statistics(self, mean: torch.Tensor, std: torch.Tensor, min_std: float = 1e-2) -> None:
        """Per-channel mean and standard deviation of the training data (std floored at ``min_std``)."""
        if mean.shape != self.data_mean.shape or std.shape != self.data_std.shape:
            raise ValueError(
                f"statistics of shape {tuple(mean.shape)} / {tuple(std.shape)}, "
                f"expected {tuple(self.data_mean.shape)}"
            )
        if not (torch.isfinite(mean).all() and torch.isfinite(std).all()):
            raise ValueError("data statistics contain NaN or inf")
        self.data_mean.copy_(mean)
        self.data_std.copy_(std.clamp(min=min_std))

    def _scalings(self, x_t: torch.Tensor, t: torch.Tensor):
        shape = (t.shape[0],) + (1,) * (x_t.ndim - 1)
        a = self.a.to(x_t.device)[t].to(x_t.dtype).reshape(shape)
        s = self.s.to(x_t.device)[t].to(x_t.dtype).reshape(shape)
        mu, sigma = self.data_mean.to(x_t.dtype), self.data_std.to(x_t.dtype)
        d = a.square() * sigma.square() + s.square()
        return a, s, mu, sigma, d

    def network_input(self, x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """``(x_t - a mu) / sqrt(d)`` (B, ...) for x_t (B, ...) and t (B,) long."""
        a, _, mu, _, d = self._scalings(x_t, t)
        return (x_t - a * mu) / d.sqrt()

    def forward(
        self, x_t: torch.Tensor, out: torch.Tensor, t: torch.Tensor, mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        """x_t and F (B, ...), t (B,) long -> x0_hat (B, ...). ``mask`` (B, T) of valid frames is taken for
        the signature of :class:`~.temporal_prior.TemporalPriorSkipX0` and not needed: every frame is its
        own."""
        a, s, mu, sigma, d = self._scalings(x_t, t)
        return mu + a * sigma.square() / d * (x_t - a * mu) + sigma * s / d.sqrt() * out
