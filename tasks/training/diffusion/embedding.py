"""The sinusoidal embedding of diffusion timesteps and sequence positions, shared by every task.

``f_k = max_period^(-k / half)`` for ``k < half = dim // 2``; the embedding of a position p is the
``half`` sines ``sin(p f_k)`` and the ``half`` cosines ``cos(p f_k)`` side by side ([Transformer]
Sec. 3.5; [DDPM]'s timestep embedding). Upstream code puts the two halves in either order: EDGE's
``SinusoidalPosEmb`` writes ``[sin, cos]`` and guided-diffusion's ``nn.timestep_embedding``
``[cos, sin]``. The order only permutes the input columns of the first layer that reads the embedding,
so a network keeps the order it was trained with: EMM ``"sin_cos"``, the text-to-motion denoisers
``"cos_sin"``.
"""

from __future__ import annotations

import math

import torch
from torch import nn

__all__ = ["EMBEDDING_ORDERS", "sinusoidal_embedding"]

EMBEDDING_ORDERS = ("sin_cos", "cos_sin")


def sinusoidal_embedding(
    positions: torch.Tensor, dim: int, order: str = "sin_cos", max_period: float = 10000.0
) -> torch.Tensor:
    """(...,) positions or timesteps -> (..., dim) float32 ``[sin, cos]`` (or ``[cos, sin]``) embedding.

    An odd ``dim`` ends with one zero channel.
    """
    if order not in EMBEDDING_ORDERS:
        raise ValueError(f"order must be one of {EMBEDDING_ORDERS}, got {order!r}")
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, device=positions.device) / max(half, 1))
    args = positions.float()[..., None] * freqs
    halves = (torch.sin(args), torch.cos(args)) if order == "sin_cos" else (torch.cos(args), torch.sin(args))
    return nn.functional.pad(torch.cat(halves, dim=-1), (0, dim % 2))
