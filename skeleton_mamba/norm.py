"""Gated RMSNorm of the Mamba-2 mixer (``mamba_ssm/ops/triton/layernorm_gated.py`` semantics)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn


def upcast(t: torch.Tensor) -> torch.Tensor:
    """Half precision to fp32; fp32 and fp64 stay as they are."""
    return t.float() if t.dtype in (torch.float16, torch.bfloat16) else t


class RMSNormGated(nn.Module):
    """RMSNorm with a SiLU gate, normalised per group of ``group_size`` channels in fp32 (fp64 stays fp64).

    ``norm_before_gate=False`` (Mamba-2): ``out = RMSNorm(y * silu(z))``;
    ``True``: ``out = RMSNorm(y) * silu(z)``. Shapes: y, z (..., d) -> (..., d).
    """

    def __init__(
        self, d: int, group_size: int | None = None, eps: float = 1e-5, norm_before_gate: bool = False
    ):
        super().__init__()
        self.group_size = group_size or d
        if d % self.group_size:
            raise ValueError(f"width {d} is not a multiple of the norm group size {self.group_size}")
        self.eps = eps
        self.norm_before_gate = norm_before_gate
        self.weight = nn.Parameter(torch.ones(d))

    def forward(self, y: torch.Tensor, z: torch.Tensor | None = None) -> torch.Tensor:
        dtype = y.dtype
        y = upcast(y)
        if z is not None and not self.norm_before_gate:
            y = y * F.silu(upcast(z))
        g = rearrange(y, "... (g c) -> ... g c", c=self.group_size)
        g = g * torch.rsqrt(g.pow(2).mean(-1, keepdim=True) + self.eps)
        y = rearrange(g, "... g c -> ... (g c)") * upcast(self.weight)
        if z is not None and self.norm_before_gate:
            y = y * F.silu(upcast(z))
        return y.to(dtype)
