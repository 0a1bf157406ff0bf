"""One Skeleton Mamba block (seed 000 Eq. 11 and supplementary Table 1).

    x (B, T, J, D)
    g = HT(LN(x))                      (B, T, G, E)     Human Tokenizer
    g = g + GS(g)                                       Group Scan (MSSD)
    x = x + HT^-1(JS(LN(g)))           (B, T, J, D)     Joint Scan, Inverse Human Tokenizer
    x = x + TS(LN(x), mask)                             bidirectional Temporal Scan
    x = x + CA(LN(x), context)                          cross-attention (when a condition is used)
    x = x + MLP(LN(x))

Pre-norm residual sublayers; the paper fixes the order of the scans but not the residual layout,
which is this project's (and the authors' released code's) reconstruction.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from skeleton_mamba.config import MixerConfig
from skeleton_mamba.cross_attention import CrossAttention
from skeleton_mamba.group_scan import GroupScan
from skeleton_mamba.joint_scan import JointScan
from skeleton_mamba.temporal_scan import TemporalScan
from skeleton_mamba.tokenizer import HumanTokenizer, InverseHumanTokenizer


class SkeletonMambaBlock(nn.Module):
    """(B, T, J, D) -> (B, T, J, D)."""

    def __init__(
        self,
        dim: int,
        groups: Sequence[Sequence[int]],
        num_joints: int,
        group_paths: Sequence[Sequence[int]],
        group_scan_shared: bool = False,
        heads: int = 4,
        mlp_dim: int = 1024,
        context_dim: int | None = None,
        dropout: float = 0.0,
        mixer: MixerConfig | None = None,
    ):
        super().__init__()
        group_size = len(groups[0])
        width = group_size * dim  # E = P * D
        self.tokenizer = HumanTokenizer(groups)
        self.inverse_tokenizer = InverseHumanTokenizer(groups, num_joints)
        self.norm_group = nn.LayerNorm(dim)
        self.group_scan = GroupScan(width, group_paths, shared=group_scan_shared, mixer=mixer)
        self.norm_joint = nn.LayerNorm(width)
        self.joint_scan = JointScan(dim, group_size, mixer=mixer)
        self.norm_time = nn.LayerNorm(dim)
        self.temporal_scan = TemporalScan(dim, mixer=mixer)
        self.cross_attention = None
        if context_dim is not None:
            self.norm_context = nn.LayerNorm(dim)
            self.cross_attention = CrossAttention(dim, context_dim, heads=heads, dropout=dropout)
        self.norm_mlp = nn.LayerNorm(dim)
        self.mlp = nn.Sequential(
            nn.Linear(dim, mlp_dim),
            nn.GELU(),
            nn.Dropout(dropout),
            nn.Linear(mlp_dim, dim),
            nn.Dropout(dropout),
        )

    def forward(
        self,
        x: torch.Tensor,
        mask: torch.Tensor | None = None,
        context: torch.Tensor | None = None,
        context_mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        g = self.tokenizer(self.norm_group(x))
        g = g + self.group_scan(g)
        x = x + self.inverse_tokenizer(self.joint_scan(self.norm_joint(g)))
        x = x + self.temporal_scan(self.norm_time(x), mask)
        if self.cross_attention is not None:
            if context is None:
                raise ValueError("this backbone was built with context_dim: pass a context (B, S, Dc)")
            x = x + self.cross_attention(self.norm_context(x), context, context_mask)
        return x + self.mlp(self.norm_mlp(x))
