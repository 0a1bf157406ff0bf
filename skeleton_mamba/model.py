"""SkeletonMamba: the backbone, N blocks over joint tokens for any registered skeleton."""

from __future__ import annotations

import torch
from torch import nn
from torch.utils.checkpoint import checkpoint

from skeleton_mamba.block import SkeletonMambaBlock
from skeleton_mamba.config import SkeletonMambaConfig
from skeleton_mamba.padding import zero_padding
from skeleton_mamba.pretrained.mixin import PretrainedMixin
from skeleton_mamba.runtime import streaming
from skeleton_mamba.runtime.compiling import CompiledStep
from skeleton_mamba.runtime.streaming import StreamState
from skeleton_mamba.skeletons import get_skeleton
from skeleton_mamba.temporal_scan import check_prefix_mask


class SkeletonMamba(PretrainedMixin, nn.Module):
    """(B, T, J, C_in) -> (B, T, J, D or C_out).

    Example::

        cfg = SkeletonMambaConfig(skeleton="ntu25", in_channels=3, dim=64, depth=2)
        y = SkeletonMamba(cfg)(torch.randn(2, 100, 25, 3))          # (2, 100, 25, 64)

    Args:
        config: a :class:`SkeletonMambaConfig` (defaults: [EgoMusic] supp. Table 2, D 128, G 5, P 6, N 8).

    ``save_pretrained`` / ``from_pretrained`` / ``push_to_hub``: :mod:`skeleton_mamba.pretrained.mixin`.

    Examples:
        >>> import torch
        >>> from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig
        >>> config = SkeletonMambaConfig(
        ...     "ntu25", in_channels=3, dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(headdim=8)
        ... )
        >>> SkeletonMamba(config)(torch.randn(2, 10, 25, 3)).shape  # (B, T, J, xyz) -> (B, T, J, dim)
        torch.Size([2, 10, 25, 16])
    """

    pretrained_task = "Skeleton Mamba backbone: (B, T, J, C) joint features to (B, T, J, D) tokens."
    pretrained_citations = ("EgoMusic", "Mamba-2")

    def __init__(self, config: SkeletonMambaConfig | None = None, **overrides):
        super().__init__()
        if config is None:
            config = SkeletonMambaConfig(**overrides)
        elif overrides:
            raise TypeError("pass either a config or keyword overrides, not both")
        self.config = config
        skeleton = get_skeleton(config.skeleton)
        self.skeleton = skeleton
        d = config.dim
        self.input_proj = (
            nn.Linear(config.in_channels, d) if config.in_channels is not None else nn.Identity()
        )
        self.joint_embedding = (
            nn.Parameter(torch.randn(skeleton.num_joints, d) * 0.02) if config.joint_embedding else None
        )
        self.blocks = nn.ModuleList(SkeletonMambaBlock(config, skeleton) for _ in range(config.depth))
        self.norm = nn.LayerNorm(d)
        self.output_proj = (
            nn.Linear(d, config.out_channels) if config.out_channels is not None else nn.Identity()
        )

    def pretrained_init_args(self) -> dict:
        """The config (keyword overrides folded in) rebuilds this backbone."""
        return {"config": self.config}

    @property
    def out_channels(self) -> int:
        return self.config.out_channels if self.config.out_channels is not None else self.config.dim

    def forward(
        self,
        x: torch.Tensor,
        mask: torch.Tensor | None = None,
        context: torch.Tensor | None = None,
        context_mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Run the backbone.

        Args:
            x: (B, T, J, C_in) per-joint features.
            mask: (B, T) bool, True on valid frames (a valid prefix per sequence; right padding).
                Padded frames never influence valid ones, whatever they hold (NaN and Inf included):
                they are replaced by zeros here and in every Temporal Scan.
            context: (B, S, Dc) condition sequence for cross-attention (when ``context_dim`` is set).
            context_mask: (B, S) bool, True on valid condition tokens.

        Returns:
            (B, T, J, D) or (B, T, J, C_out).
        """
        if x.dim() != 4 or x.shape[2] != self.skeleton.num_joints:
            raise ValueError(
                f"expected (B, T, {self.skeleton.num_joints}, C) for skeleton {self.skeleton.name}, "
                f"got {tuple(x.shape)}"
            )
        if mask is not None:
            check_prefix_mask(mask)
            x = zero_padding(x, mask)  # NaN / Inf in the padding would survive a multiplication by 0
        h = self.input_proj(x)
        if self.joint_embedding is not None:
            h = h + self.joint_embedding
        for block in self.blocks:
            if self.config.gradient_checkpointing and self.training and torch.is_grad_enabled():
                h = checkpoint(block, h, mask, context, context_mask, use_reentrant=False)
            else:
                h = block(h, mask=mask, context=context, context_mask=context_mask)
        return self.output_proj(self.norm(h))

    def init_state(
        self, batch: int, dtype: torch.dtype | None = None, device: torch.device | None = None
    ) -> StreamState:
        """Zero recurrent state for ``batch`` streams (causal backbones; see
        ``skeleton_mamba.runtime.streaming``)."""
        return streaming.init_state(self, batch, dtype, device)

    def step(
        self,
        x: torch.Tensor,
        state: StreamState,
        context: torch.Tensor | None = None,
        context_mask: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, StreamState]:
        """One frame (B, J, C_in) -> (B, J, D or C_out), updating ``state`` in place.

        Stepping through frames 0..T-1 equals ``forward`` on the whole sequence (causal backbones)
        when every step gets the ``context`` of the batch call. Inference only (no autograd).
        """
        return streaming.step(self, x, state, context, context_mask)

    def compile_step(self, freezing: bool = True, mode: str | None = None) -> CompiledStep:
        """:meth:`step` through ``torch.compile`` (inductor, frozen weights; compiles on the first call).

        Same signature and results as :meth:`step`; see :mod:`skeleton_mamba.runtime.compiling`.
        """
        return CompiledStep(self, freezing, mode)
