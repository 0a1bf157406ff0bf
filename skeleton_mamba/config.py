"""Typed configuration of the Skeleton Mamba backbone (defaults: [EgoMusic] supp. Table 2)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from skeleton_mamba.ssd.discretize import NO_DT_LIMIT

__all__ = ["ConfigValueError", "MixerConfig", "SkeletonMambaConfig"]


class ConfigValueError(ValueError):
    """A config field outside its range, raised when the config is made: ``owner.field = value: rule``.

    ``owner`` (the dataclass), ``field``, ``value`` and ``rule`` are kept so that a reader of a file (a
    pretrained folder's ``config.json``, :mod:`skeleton_mamba.pretrained.codec`) names the field by its
    place in the file instead.
    """

    def __init__(self, owner: str, field: str, value: Any, rule: str) -> None:
        self.owner, self.field, self.value, self.rule = owner, field, value, rule
        super().__init__(f"{owner}.{field} = {value!r}: {rule}")


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_real(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _check_counts(config: Any, names: tuple[str, ...], optional: tuple[str, ...] = ()) -> None:
    """Each field of ``names`` (and of ``optional``, unless None) an integer >= 1."""
    owner = type(config).__name__
    for name in (*names, *optional):
        value = getattr(config, name)
        if value is None and name in optional:
            continue
        if not _is_int(value) or value < 1:
            rule = "must be an integer >= 1" + (" or null" if name in optional else "")
            raise ConfigValueError(owner, name, value, rule)


def _pair(config: Any, name: str) -> tuple[float, float]:
    value = getattr(config, name)
    if (
        not isinstance(value, (tuple, list))
        or len(value) != 2
        or not all(_is_real(v) and not math.isnan(v) for v in value)
    ):
        raise ConfigValueError(type(config).__name__, name, value, "must be a pair of numbers (min, max)")
    return float(value[0]), float(value[1])


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

    def __post_init__(self) -> None:
        """The ranges ``mamba_ssm.Mamba2`` assumes, checked when the config is made (a ``config.json``, a
        recipe, a checkpoint's hyper-parameters), not at the first forward: every size an integer >= 1,
        ``0 < dt_min <= dt_max``, ``dt_init_floor >= 0``, ``0 < A_init_range[0] <= A_init_range[1]``,
        ``0 <= dt_limit[0] < dt_limit[1]`` (finite, except an infinite max)."""
        _check_counts(self, ("d_state", "d_conv", "expand", "headdim", "ngroups", "chunk_size"), ("d_ssm",))
        owner = type(self).__name__
        for name, floor in (("dt_min", False), ("dt_max", False), ("dt_init_floor", True)):
            value = getattr(self, name)
            if not _is_real(value) or not math.isfinite(value) or not (value >= 0 if floor else value > 0):
                raise ConfigValueError(
                    owner, name, value, f"must be a finite number {'>=' if floor else '>'} 0"
                )
        if self.dt_max < self.dt_min:
            raise ConfigValueError(owner, "dt_max", self.dt_max, f"must be >= dt_min ({self.dt_min!r})")
        low, high = _pair(self, "A_init_range")
        if not (0 < low <= high < math.inf):
            rule = "must satisfy 0 < min <= max, both finite (A = -exp(A_log) is drawn from it)"
            raise ConfigValueError(owner, "A_init_range", self.A_init_range, rule)
        low, high = _pair(self, "dt_limit")
        if not (0 <= low < high and math.isfinite(low)):
            rule = "must satisfy 0 <= min < max (min finite, max may be inf)"
            raise ConfigValueError(owner, "dt_limit", self.dt_limit, rule)


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
            ``skeleton_mamba.runtime.streaming``). ``False`` (default): the paper's bidirectional scan.
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

    def __post_init__(self) -> None:
        """Checked when made (a ``config.json``, a recipe, a checkpoint's hyper-parameters), not at the first
        forward: ``dim``, ``depth``, ``heads``, ``mlp_dim`` integers >= 1; ``in_channels``,
        ``out_channels``, ``context_dim``, ``cpu_slice_elements`` null or integers >= 1; ``0 <= dropout < 1``;
        ``dim`` a multiple of ``heads`` when cross-attention is on (``context_dim``)."""
        _check_counts(
            self,
            ("dim", "depth", "heads", "mlp_dim"),
            ("in_channels", "out_channels", "context_dim", "cpu_slice_elements"),
        )
        owner = type(self).__name__
        if not _is_real(self.dropout) or not 0 <= self.dropout < 1:
            raise ConfigValueError(owner, "dropout", self.dropout, "must be a number from 0 to below 1")
        if self.context_dim is not None and self.dim % self.heads:
            rule = f"must be a multiple of heads ({self.heads}) for the cross-attention (context_dim is set)"
            raise ConfigValueError(owner, "dim", self.dim, rule)
