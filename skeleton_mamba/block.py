"""One Skeleton Mamba block ([EgoMusic] supp. Eq. 11 and Table 1).

    x (B, T, J, D)
    g = HT(LN(x))                      (B, T, G, E)     Human Tokenizer
    g = g + GS(g)                                       Group Scan (MSSD)
    x = x + HT^-1(JS(LN(g)))           (B, T, J, D)     Joint Scan, Inverse Human Tokenizer
    x = x + TS(LN(x), mask)                             bidirectional Temporal Scan (or forward-only)
    x = x + CA(LN(x), context)                          cross-attention (when a condition is used)
    x = x + MLP(LN(x))

Pre-norm residual sublayers; the paper fixes the order of the scans but not the residual layout,
which is this project's (and the authors' released code's) reconstruction. The frame-wise part (up
to the Joint Scan) and the token-wise part (cross-attention, MLP) run on slices of frames on a CPU,
the Temporal Scan on slices of joint sequences (``skeleton_mamba.runtime.slicing``; exact).
"""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba.config import SkeletonMambaConfig
from skeleton_mamba.cross_attention import CrossAttention
from skeleton_mamba.group_scan import GroupScan
from skeleton_mamba.joint_scan import JointScan
from skeleton_mamba.runtime.slicing import map_slices, slice_length
from skeleton_mamba.skeletons import Skeleton
from skeleton_mamba.temporal_scan import TemporalScan
from skeleton_mamba.tokenizer import HumanTokenizer, InverseHumanTokenizer


class SkeletonMambaBlock(nn.Module):
    """(B, T, J, D) -> (B, T, J, D).

    Args:
        config: the backbone's settings, passed whole (``dim``, ``group_paths``, ``group_scan_shared``,
            ``heads``, ``mlp_dim``, ``context_dim``, ``dropout``, ``mixer``, ``cpu_slice_elements``,
            ``causal``; the defaults are :class:`~skeleton_mamba.config.SkeletonMambaConfig`'s).
        skeleton: the joints' groups (``config.group_paths`` ``None``: its group paths).

    Examples:
        >>> import torch
        >>> from skeleton_mamba import MixerConfig, SkeletonMambaBlock, SkeletonMambaConfig, get_skeleton
        >>> config = SkeletonMambaConfig("ntu25", dim=16, heads=2, mlp_dim=32, mixer=MixerConfig(headdim=8))
        >>> block = SkeletonMambaBlock(config, get_skeleton("ntu25"))
        >>> block(torch.randn(2, 10, 25, 16)).shape  # Group, Joint and Temporal Scan, MLP: (B, T, J, D)
        torch.Size([2, 10, 25, 16])
    """

    def __init__(self, config: SkeletonMambaConfig, skeleton: Skeleton):
        super().__init__()
        dim, mixer, groups = config.dim, config.mixer, skeleton.groups
        group_paths = skeleton.group_paths if config.group_paths is None else config.group_paths
        self.slice_elements = config.cpu_slice_elements
        self.mlp_dim = config.mlp_dim
        group_size = len(groups[0])
        width = group_size * dim  # E = P * D
        self.tokenizer = HumanTokenizer(groups)
        self.inverse_tokenizer = InverseHumanTokenizer(groups, skeleton.num_joints)
        self.norm_group = nn.LayerNorm(dim)
        self.group_scan = GroupScan(
            width, [tuple(p) for p in group_paths], shared=config.group_scan_shared, mixer=mixer
        )
        self.norm_joint = nn.LayerNorm(width)
        self.joint_scan = JointScan(dim, group_size, mixer=mixer)
        self.norm_time = nn.LayerNorm(dim)
        self.temporal_scan = TemporalScan(
            dim, mixer=mixer, slice_elements=self.slice_elements, causal=config.causal
        )
        self.cross_attention = None
        if config.context_dim is not None:
            self.norm_context = nn.LayerNorm(dim)
            self.cross_attention = CrossAttention(
                dim, config.context_dim, heads=config.heads, dropout=config.dropout
            )
        self.norm_mlp = nn.LayerNorm(dim)
        self.mlp = nn.Sequential(
            nn.Linear(dim, config.mlp_dim),
            nn.GELU(),
            nn.Dropout(config.dropout),
            nn.Linear(config.mlp_dim, dim),
            nn.Dropout(config.dropout),
        )

    def forward(
        self,
        x: torch.Tensor,
        mask: torch.Tensor | None = None,
        context: torch.Tensor | None = None,
        context_mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        if self.cross_attention is not None and context is None:
            raise ValueError("this backbone was built with context_dim: pass a context (B, S, Dc)")
        b, j = x.shape[0], x.shape[2]
        # Widest intermediate per frame: the Group Scan's projected path sequence.
        per_frame = b * self.group_scan.path_elements
        x = map_slices(self.spatial, 1, slice_length(x, 1, per_frame, self.slice_elements), x)
        x = x + self.temporal_scan(self.norm_time(x), mask)
        # Per frame: the MLP's hidden layer, or the attention scores over the condition.
        width = self.mlp_dim
        if self.cross_attention is not None:
            width = max(width, self.cross_attention.heads * context.shape[1])
        frames = slice_length(x, 1, b * j * width, self.slice_elements)
        return map_slices(lambda h: self.pointwise(h, context, context_mask), 1, frames, x)

    def spatial(self, x: torch.Tensor, ops=None) -> torch.Tensor:
        """The frame-wise sublayers: Group Scan, then Joint Scan back to joints. (B, T, J, D).

        ``ops``: the scans' projections and mixers for one frame
        (:class:`~skeleton_mamba.runtime.frame_ops.FrameOps`, see :meth:`GroupScan.forward`); ``None``: the
        modules' own.
        """
        g = self.tokenizer(self.norm_group(x))
        g = g + self.group_scan(g, ops)
        return x + self.inverse_tokenizer(self.joint_scan(self.norm_joint(g), ops))

    def pointwise(
        self, x: torch.Tensor, context: torch.Tensor | None, context_mask: torch.Tensor | None
    ) -> torch.Tensor:
        """The token-wise sublayers: cross-attention (when built with a context) and MLP. (B, T, J, D)."""
        if self.cross_attention is not None:
            x = x + self.cross_attention(self.norm_context(x), context, context_mask)
        return x + self.mlp(self.norm_mlp(x))
