"""Cross-attention from joint tokens to a condition sequence ([EgoMusic] supp. Table 1, row 9)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from skeleton_mamba.padding import zero_padding


class CrossAttention(nn.Module):
    """Queries (B, T, J, D) attend to a condition (B, S, Dc) -> (B, T, J, D).

    Every joint token of every frame attends over the whole condition sequence, which may be
    padded: ``context_mask`` (B, S) bool marks valid condition tokens; padded tokens are replaced by
    zeros before the projections, so whatever they hold (NaN included) cannot reach the output.
    """

    def __init__(self, dim: int, context_dim: int, heads: int = 4, dropout: float = 0.0):
        super().__init__()
        if dim % heads:
            raise ValueError(f"width {dim} is not divisible by {heads} heads")
        self.heads = heads
        self.dropout = dropout
        self.to_q = nn.Linear(dim, dim, bias=False)
        self.to_kv = nn.Linear(context_dim, 2 * dim, bias=False)
        self.out = nn.Linear(dim, dim)

    def forward(
        self, x: torch.Tensor, context: torch.Tensor, context_mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        b, t, j, _ = x.shape
        attn_mask = None
        if context_mask is not None:
            attn_mask = context_mask[:, None, None, :]
            context = zero_padding(context, context_mask)  # a weight of 0 times a NaN value is NaN
        q = rearrange(self.to_q(x), "b t j (h c) -> b h (t j) c", h=self.heads)
        k, v = rearrange(self.to_kv(context), "b s (two h c) -> two b h s c", two=2, h=self.heads)
        y = F.scaled_dot_product_attention(
            q, k, v, attn_mask=attn_mask, dropout_p=self.dropout if self.training else 0.0
        )
        return self.out(rearrange(y, "b h (t j) c -> b t j (h c)", t=t, j=j))
