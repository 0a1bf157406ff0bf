"""Gaussian diffusion with x0 prediction: forward noising, the training target, the true posterior.

Notation of [DDPM] with the *cumulative product* ``alpha_bar_t = prod_{s<=t} (1 - beta_s)``;
[EgoMusic] supp. Eq. 7 (posterior mean with "alpha-hat = sum of alpha_s") is garbled and is NOT followed.
"""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba.tasks.training.diffusion.schedule import NoiseSchedule

__all__ = ["GaussianDiffusion"]


def _extract(values: torch.Tensor, t: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """values (S,), t (B,) -> (B, 1, ..., 1) broadcastable against ``like`` (B, ...), in its dtype."""
    out = values.to(like.device)[t.to(like.device)].to(like.dtype)
    return out.reshape(t.shape[0], *([1] * (like.ndim - 1)))


class GaussianDiffusion(nn.Module):
    """Holds a :class:`NoiseSchedule` as buffers (they follow ``.to(device)``) and its Gaussian maths.

    Args:
        num_steps: diffusion steps T ([EgoMusic] supp. Table 2: 1000).
        schedule: ``"cosine"`` (EDGE, EMM).
        cosine_s: the offset s of the cosine schedule.
    """

    def __init__(self, num_steps: int = 1000, schedule: str = "cosine", cosine_s: float = 0.008):
        super().__init__()
        if schedule != "cosine":
            raise ValueError(f"unknown noise schedule {schedule!r} (available: 'cosine')")
        sched = NoiseSchedule.cosine(num_steps, cosine_s)
        self.num_steps = num_steps
        for name in (
            "betas",
            "alphas_cumprod",
            "alphas_cumprod_prev",
            "posterior_variance",
            "posterior_log_variance_clipped",
            "posterior_mean_coef1",
            "posterior_mean_coef2",
        ):
            self.register_buffer(name, getattr(sched, name), persistent=False)

    def sample_timesteps(
        self, batch: int, device: torch.device | str | None = None, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """Uniform timesteps (batch,) long in [0, T)."""
        return torch.randint(0, self.num_steps, (batch,), device=device, generator=generator)

    def q_sample(self, x0: torch.Tensor, t: torch.Tensor, noise: torch.Tensor | None = None) -> torch.Tensor:
        """x_t = sqrt(alpha_bar_t) x0 + sqrt(1 - alpha_bar_t) eps; x0 (B, ...), t (B,)."""
        if noise is None:
            noise = torch.randn_like(x0)
        abar = _extract(self.alphas_cumprod, t, x0)
        return abar.sqrt() * x0 + (1.0 - abar).sqrt() * noise

    def training_pair(
        self,
        x0: torch.Tensor,
        t: torch.Tensor | None = None,
        noise: torch.Tensor | None = None,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Noisy input, its timesteps and the x0-prediction target: ``(x_t, t, x0)``.

        The denoiser is trained to return ``x0`` from ``(x_t, t, cond)`` (x0 parameterisation, EDGE/EMM).
        """
        if t is None:
            t = self.sample_timesteps(x0.shape[0], x0.device, generator)
        if noise is None:
            noise = torch.randn(x0.shape, generator=generator, device=x0.device, dtype=x0.dtype)
        return self.q_sample(x0, t, noise), t, x0

    def q_posterior(
        self, x0: torch.Tensor, x_t: torch.Tensor, t: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Mean, variance and clipped log-variance of q(x_{t-1} | x_t, x0), each broadcast to x (B, ...)."""
        coef1 = _extract(self.posterior_mean_coef1, t, x_t)
        mean = coef1 * x0 + _extract(self.posterior_mean_coef2, t, x_t) * x_t
        var = _extract(self.posterior_variance, t, x_t)
        log_var = _extract(self.posterior_log_variance_clipped, t, x_t)
        return mean, var.expand_as(x_t), log_var.expand_as(x_t)

    def predict_noise_from_x0(self, x_t: torch.Tensor, t: torch.Tensor, x0: torch.Tensor) -> torch.Tensor:
        """eps = (x_t - sqrt(alpha_bar_t) x0) / sqrt(1 - alpha_bar_t)."""
        abar = _extract(self.alphas_cumprod, t, x_t)
        return (x_t - abar.sqrt() * x0) / (1.0 - abar).sqrt()
