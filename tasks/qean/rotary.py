"""Spin Position Embedding ([QEAN] Sec. 3.3) = rotary position embedding ([RoFormer]).

Query and key of the token at position ``s`` are rotated pairwise, consecutive coordinates
``(x_(2i), x_(2i+1))`` by the angle ``s theta_i`` (Eqs. 21-22)::

    (x1, x2) -> (x1 cos(s theta) - x2 sin(s theta), x2 cos(s theta) + x1 sin(s theta))

so ``<O_q(x_s, s), O_k(x_t, t)>`` depends on ``s - t`` only (Eqs. 11, 24). The frequencies are not given
by [QEAN]; RoFormer's ``theta_i = base^(-2 i / d)``, ``base = 10000`` is used. An odd last channel is
left unrotated.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["SpinPositionEmbedding", "apply_rotary"]


def apply_rotary(x: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor) -> torch.Tensor:
    """Rotate consecutive channel pairs of ``x`` (..., T, d) by angles with ``cos``/``sin`` (T, d // 2)."""
    pairs = cos.shape[-1]
    x1, x2 = x[..., 0 : 2 * pairs : 2], x[..., 1 : 2 * pairs : 2]
    rotated = torch.stack([x1 * cos - x2 * sin, x2 * cos + x1 * sin], dim=-1).flatten(-2)
    return torch.cat([rotated, x[..., 2 * pairs :]], dim=-1)


class SpinPositionEmbedding(nn.Module):
    """Rotary tables for a head width ``head_dim``; ``forward(q, k)`` rotates both at positions 0..T-1.

    Args:
        head_dim: channels per attention head (d).
        base: RoFormer frequency base (theta_i = base^(-2 i / d)).
    """

    def __init__(self, head_dim: int, base: float = 10000.0) -> None:
        super().__init__()
        pairs = head_dim // 2
        inv_freq = base ** (-torch.arange(pairs, dtype=torch.float64) * 2.0 / head_dim)
        self.register_buffer("inv_freq", inv_freq, persistent=False)
        self._table: tuple[int, torch.dtype, torch.device, torch.Tensor, torch.Tensor] | None = None

    def cos_sin(
        self, length: int, dtype: torch.dtype, device: torch.device, offset: int = 0
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``cos, sin`` of ``(offset + t) theta_i``, each (length, d // 2), cached.

        A table built under ``torch.inference_mode`` is rebuilt for use with autograd.
        """
        need = offset + length
        table = self._table
        stale = table is not None and table[3].is_inference() and not torch.is_inference_mode_enabled()
        if stale or table is None or table[0] < need or table[1] != dtype or table[2] != device:
            positions = torch.arange(need, dtype=torch.float64, device=device)
            angles = positions[:, None] * self.inv_freq.to(device)[None, :]
            table = (need, dtype, device, angles.cos().to(dtype), angles.sin().to(dtype))
            self._table = table
        return table[3][offset:need], table[4][offset:need]

    def rotate(self, x: torch.Tensor, offset: int = 0) -> torch.Tensor:
        """Rotate ``x`` (..., T, d) at positions ``offset .. offset + T - 1``."""
        cos, sin = self.cos_sin(x.shape[-2], x.dtype, x.device, offset)
        return apply_rotary(x, cos, sin)

    def forward(self, q: torch.Tensor, k: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Rotate ``q`` (..., N, d) and ``k`` (..., M, d) at positions 0..N-1 and 0..M-1."""
        cos, sin = self.cos_sin(max(q.shape[-2], k.shape[-2]), q.dtype, q.device)
        return (
            apply_rotary(q, cos[: q.shape[-2]], sin[: q.shape[-2]]),
            apply_rotary(k, cos[: k.shape[-2]], sin[: k.shape[-2]]),
        )
