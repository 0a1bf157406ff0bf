"""The sinusoidal embedding of diffusion timesteps and sequence positions, shared by every task.

``f_k = max_period^(-k / half)`` for ``k < half = dim // 2``; the embedding of a position p is the
``half`` sines ``sin(p f_k)`` and the ``half`` cosines ``cos(p f_k)`` side by side ([Transformer]
Sec. 3.5; [DDPM]'s timestep embedding). Upstream code puts the two halves in either order: EDGE's
``SinusoidalPosEmb`` writes ``[sin, cos]`` and guided-diffusion's ``nn.timestep_embedding``
``[cos, sin]``, and MDM's ``PositionalEncoding`` ([MDM], after [Transformer]) interleaves them (sines
in the even channels, cosines in the odd ones). The order only permutes the input columns of the first
layer that reads the embedding, so a network keeps the order it was trained with: EMM ``"sin_cos"``, the
text-to-motion denoisers ``"cos_sin"``, the MDM-style transformer baseline's positions ``"interleaved"``.
"""

from __future__ import annotations

import math

import torch
from torch import nn

__all__ = ["EMBEDDING_ORDERS", "sinusoidal_embedding"]

EMBEDDING_ORDERS = ("sin_cos", "cos_sin", "interleaved")


def sinusoidal_embedding(
    positions: torch.Tensor, dim: int, order: str = "sin_cos", max_period: float = 10000.0
) -> torch.Tensor:
    """(...,) positions or timesteps -> (..., dim) float32 ``[sin, cos]`` (or ``[cos, sin]``, or the two
    interleaved) embedding.

    An odd ``dim`` ends with one zero channel. ``"interleaved"`` computes the frequencies as MDM's
    ``PositionalEncoding`` does (``exp(2k * -log(max_period) / dim)``), so its values are that module's bit
    for bit; the same frequencies up to float32 rounding.

    Examples:
        >>> import torch
        >>> e = sinusoidal_embedding(torch.arange(3), 4)
        >>> e.shape, e[0].tolist()
        (torch.Size([3, 4]), [0.0, 0.0, 1.0, 1.0])
        >>> sinusoidal_embedding(torch.arange(3), 4, order="interleaved")[0].tolist()
        [0.0, 1.0, 0.0, 1.0]
    """
    if order not in EMBEDDING_ORDERS:
        raise ValueError(f"order must be one of {EMBEDDING_ORDERS}, got {order!r}")
    half = dim // 2
    device = positions.device
    if order == "interleaved":
        steps = torch.arange(0, 2 * half, 2, device=device, dtype=torch.float32)
        freqs = torch.exp(steps * (-math.log(max_period) / max(2 * half, 1)))
    else:
        freqs = torch.exp(-math.log(max_period) * torch.arange(half, device=device) / max(half, 1))
    args = positions.float()[..., None] * freqs
    sin, cos = torch.sin(args), torch.cos(args)
    if order == "interleaved":
        embedding = torch.stack((sin, cos), dim=-1).flatten(-2)
    else:
        embedding = torch.cat((sin, cos) if order == "sin_cos" else (cos, sin), dim=-1)
    return nn.functional.pad(embedding, (0, dim % 2))
