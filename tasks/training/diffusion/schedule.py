"""Noise schedules: the cosine schedule of [IDDPM], as used by EDGE and EMM.

[EgoMusic] supp. Eqs. 5 and 7 write ``alpha_t`` for the cumulative product and then define ``alpha-hat`` as a
*sum*; that is a misprint. We use standard [DDPM] notation:
``alpha_t = 1 - beta_t`` and ``alpha_bar_t = prod_{s<=t} alpha_s`` (the cumulative product).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

__all__ = ["cosine_betas", "NoiseSchedule"]


def cosine_betas(num_steps: int = 1000, s: float = 0.008, max_beta: float = 0.999) -> torch.Tensor:
    """Betas (num_steps,) float64 of the cosine schedule.

    ``f(u) = cos^2((u + s) / (1 + s) * pi / 2)``, ``beta_i = min(1 - f((i + 1) / T) / f(i / T), max_beta)``
    (EDGE ``model/diffusion.py``).
    """
    if num_steps < 1:
        raise ValueError(f"num_steps must be >= 1, got {num_steps}")

    def f(u: float) -> float:
        return math.cos((u + s) / (1 + s) * math.pi / 2) ** 2

    betas = [min(1.0 - f((i + 1) / num_steps) / f(i / num_steps), max_beta) for i in range(num_steps)]
    return torch.tensor(betas, dtype=torch.float64)


@dataclass(frozen=True)
class NoiseSchedule:
    """All per-step constants (each a (num_steps,) float64 tensor) derived from ``betas``.

    Attributes:
        betas: beta_t.
        alphas: alpha_t = 1 - beta_t.
        alphas_cumprod: alpha_bar_t = prod_{s<=t} alpha_s.
        alphas_cumprod_prev: alpha_bar_{t-1} with alpha_bar_{-1} = 1.
        posterior_variance: beta_t (1 - alpha_bar_{t-1}) / (1 - alpha_bar_t) (0 at t = 0).
        posterior_log_variance_clipped: its log, with the t = 0 entry replaced by that of t = 1.
        posterior_mean_coef1: coefficient of x0 in the posterior mean,
            beta_t sqrt(alpha_bar_{t-1}) / (1 - alpha_bar_t).
        posterior_mean_coef2: coefficient of x_t, (1 - alpha_bar_{t-1}) sqrt(alpha_t) / (1 - alpha_bar_t).
    """

    betas: torch.Tensor
    alphas: torch.Tensor
    alphas_cumprod: torch.Tensor
    alphas_cumprod_prev: torch.Tensor
    posterior_variance: torch.Tensor
    posterior_log_variance_clipped: torch.Tensor
    posterior_mean_coef1: torch.Tensor
    posterior_mean_coef2: torch.Tensor

    @property
    def num_steps(self) -> int:
        return int(self.betas.shape[0])

    @classmethod
    def from_betas(cls, betas: torch.Tensor) -> NoiseSchedule:
        betas = betas.to(torch.float64)
        values_known = betas.device.type != "meta"  # a meta build (sizes only) has no values to check
        if betas.ndim != 1 or (values_known and not bool(((betas > 0) & (betas < 1)).all())):
            raise ValueError("betas must be a 1-D tensor with values in (0, 1)")
        alphas = 1.0 - betas
        alphas_cumprod = torch.cumprod(alphas, dim=0)
        alphas_cumprod_prev = torch.cat([alphas_cumprod.new_ones(1), alphas_cumprod[:-1]])
        posterior_variance = betas * (1.0 - alphas_cumprod_prev) / (1.0 - alphas_cumprod)
        clipped = posterior_variance.clone()
        if clipped.numel() > 1:
            clipped[0] = posterior_variance[1]
        return cls(
            betas=betas,
            alphas=alphas,
            alphas_cumprod=alphas_cumprod,
            alphas_cumprod_prev=alphas_cumprod_prev,
            posterior_variance=posterior_variance,
            posterior_log_variance_clipped=torch.log(clipped.clamp_min(1e-20)),
            posterior_mean_coef1=betas * alphas_cumprod_prev.sqrt() / (1.0 - alphas_cumprod),
            posterior_mean_coef2=(1.0 - alphas_cumprod_prev) * alphas.sqrt() / (1.0 - alphas_cumprod),
        )

    @classmethod
    def cosine(cls, num_steps: int = 1000, s: float = 0.008) -> NoiseSchedule:
        """The cosine schedule (EDGE / EMM: 1000 steps)."""
        return cls.from_betas(cosine_betas(num_steps, s))
