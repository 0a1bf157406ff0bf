"""Typed configuration of the Skeleton Mamba backbone (defaults: [EgoMusic] supp. Table 2)."""

from __future__ import annotations

from dataclasses import dataclass

from skeleton_mamba.ssd.discretize import NO_DT_LIMIT


@dataclass
class MixerConfig:
    """Mamba-2 mixer settings (names and meanings as in ``mamba_ssm.modules.mamba2.Mamba2``).

    The defaults suit small widths (D = 128 per joint): d_inner = expand * width, heads of
    ``headdim`` channels, state size ``d_state``.

    Options of ``mamba_ssm`` with its meaning (defaults are its defaults, which give [Mamba-2]'s block):
    ``d_ssm``: the SSM runs on this many of the ``d_inner`` channels, the remaining ``d_inner - d_ssm``
    are a gated MLP ``silu(z0) * x0`` concatenated in front of the SSM output (``None``: all of them);
    ``D_has_hdim``: one skip weight D per channel ``(d_ssm,)`` instead of per head; ``rmsnorm``:
    gated RMSNorm after the SSM (``False``: ``y * silu(z)`` and no ``norm.weight``); ``norm_before_gate``:
    ``RMSNorm(y) * silu(z)`` instead of ``RMSNorm(y * silu(z))``; ``dt_limit``: clamp of
    ``softplus(dt + dt_bias)`` to ``(min, max)``; ``bias``: biases of ``in_proj`` and ``out_proj``;
    ``conv_bias``: bias of the causal convolution.

    Examples:
        >>> from skeleton_mamba import MixerConfig
        >>> config = MixerConfig(d_state=16, headdim=8)
        >>> config.expand, config.chunk_size  # inner width = expand * d_model, split in heads of headdim
        (2, 64)
    """

    d_state: int = 64
    d_conv: int = 4
    expand: int = 2
    headdim: int = 64
    ngroups: int = 1
    chunk_size: int = 64
    dt_min: float = 0.001
    dt_max: float = 0.1
    dt_init_floor: float = 1e-4
    A_init_range: tuple[float, float] = (1.0, 16.0)
    d_ssm: int | None = None
    D_has_hdim: bool = False
    rmsnorm: bool = True
    norm_before_gate: bool = False
    dt_limit: tuple[float, float] = NO_DT_LIMIT
    bias: bool = False
    conv_bias: bool = True
    use_kernel: bool = True  # use mamba-ssm's Triton kernel on CUDA when installed


@dataclass
class SkeletonMambaConfig:
    """The backbone: ``depth`` SkeletonMamba blocks over (B, T, J, D) joint tokens.

    Attributes:
        skeleton: ``smpl24`` | ``humanml3d22`` | ``ntu25`` | ``openpose18`` (joints, groups, mirror).
        in_channels: per-joint input features C (``None``: the input already has width ``dim``).
        out_channels: per-joint output features (``None``: return width ``dim``).
        dim: D, the width of one joint token (E = P * D for a group token).
        depth: N, the number of blocks.
        group_paths: the group orders of the Group Scan (``None``: the authors' 8 paths for
            5 groups, else all groups in index order).
        group_scan_shared: ``False`` scans the concatenated paths as one sequence ([EgoMusic] supp. Eq. 13);
            ``True`` scans each path separately with shared weights (the frame-averaging F, Eq. 18).
        heads: attention heads of the optional cross-attention.
        mlp_dim: hidden width of the per-joint MLP.
        context_dim: width of a condition sequence for cross-attention (``None``: no cross-attention).
        joint_embedding: add a learned embedding per joint before the first block.
        dropout: dropout in the MLP and attention.
        gradient_checkpointing: recompute each block in the backward pass instead of storing its
            activations (the paper's size at batch 4 x 150 frames needs about 30 GB in fp32 without it).
        mixer: settings of every Mamba-2 mixer.
        causal: a forward-only Temporal Scan (no backward direction), so frame t depends on frames
            <= t only; such a backbone also runs frame by frame (``init_state`` / ``step``,
            ``skeleton_mamba.streaming``). ``False`` (default): the paper's bidirectional scan.
        cpu_slice_elements: on a CPU, frame-wise sublayers run on slices of frames and the Temporal
            Scan on slices of joint sequences, each slice holding at most about this many elements
            of its widest intermediate (4 Mi elements: 16 MB in fp32), so intermediates stay in
            cache and off fresh page-faulting mappings; exact, as frames and sequences are
            independent. ``None``: one call over everything. Not used on CUDA.

    Examples:
        >>> from skeleton_mamba import SkeletonMambaConfig
        >>> config = SkeletonMambaConfig(skeleton="smpl24", in_channels=6, dim=128, depth=8)  # [EgoMusic]
        >>> config.dim, config.depth, config.mlp_dim  # D, N and the MLP width
        (128, 8, 1024)
    """

    skeleton: str = "smpl24"
    in_channels: int | None = None
    out_channels: int | None = None
    dim: int = 128
    depth: int = 8
    group_paths: list[list[int]] | None = None
    group_scan_shared: bool = False
    heads: int = 4
    mlp_dim: int = 1024
    context_dim: int | None = None
    joint_embedding: bool = True
    dropout: float = 0.0
    gradient_checkpointing: bool = False
    mixer: MixerConfig | None = None
    causal: bool = False
    cpu_slice_elements: int | None = 4_194_304
