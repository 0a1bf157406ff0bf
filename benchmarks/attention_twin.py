"""The attention twin of SkeletonMamba, a baseline for benchmarks only.

Same structure, width and depth as the backbone, with the scans replaced by attention: each block
attends over the joints within each frame, then over time for each joint, then applies the MLP.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn


class SelfAttention(nn.Module):
    """Multi-head self-attention over the second-to-last axis: (N, L, D) -> (N, L, D)."""

    def __init__(self, dim: int, heads: int):
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(dim, 3 * dim, bias=False)
        self.out = nn.Linear(dim, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        q, k, v = rearrange(self.qkv(x), "n l (three h c) -> three n h l c", three=3, h=self.heads)
        return self.out(rearrange(F.scaled_dot_product_attention(q, k, v), "n h l c -> n l (h c)"))


class AttentionTwinBlock(nn.Module):
    def __init__(self, dim: int, heads: int, mlp_dim: int):
        super().__init__()
        self.norm_joint, self.joint_attn = nn.LayerNorm(dim), SelfAttention(dim, heads)
        self.norm_time, self.time_attn = nn.LayerNorm(dim), SelfAttention(dim, heads)
        self.norm_mlp = nn.LayerNorm(dim)
        self.mlp = nn.Sequential(nn.Linear(dim, mlp_dim), nn.GELU(), nn.Linear(mlp_dim, dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, t, j, _ = x.shape
        h = rearrange(self.norm_joint(x), "b t j d -> (b t) j d")
        x = x + rearrange(self.joint_attn(h), "(b t) j d -> b t j d", b=b)
        h = rearrange(self.norm_time(x), "b t j d -> (b j) t d")
        x = x + rearrange(self.time_attn(h), "(b j) t d -> b t j d", b=b)
        return x + self.mlp(self.norm_mlp(x))


class AttentionTwin(nn.Module):
    """(B, T, J, C_in) -> (B, T, J, D)."""

    def __init__(
        self,
        in_channels: int,
        num_joints: int,
        dim: int = 128,
        depth: int = 8,
        heads: int = 4,
        mlp_dim: int = 1024,
    ):
        super().__init__()
        self.input_proj = nn.Linear(in_channels, dim)
        self.joint_embedding = nn.Parameter(torch.randn(num_joints, dim) * 0.02)
        self.blocks = nn.ModuleList(AttentionTwinBlock(dim, heads, mlp_dim) for _ in range(depth))
        self.norm = nn.LayerNorm(dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.input_proj(x) + self.joint_embedding
        for block in self.blocks:
            h = block(h)
        return self.norm(h)
