"""QEAN network ([QEAN] Secs. 3.1 and 4.2), pure torch.

Data flow for a seed motion Y (B, 120, 219) and music features Z (B, 240, 35), aligned at frame 0::

    h^y = f_mot(Y)      motion encoder: Linear 219 -> 800, transformer with Spin Position Embedding
                        (or, in the Mamba variant, SkeletonMamba over 24 joint tokens + Linear -> 800)
    h^z = f_audio(Z)    audio encoder: Linear 35 -> 800, transformer with Spin Position Embedding
    x   = [h^y ; h^z]   (B, 360, 800), concatenated along time (FACT's cross-modal input)
    x   = cross-modal transformer whose attention is Quaternion Rotary Attention (rows of Q, K read as
          quaternions, :mod:`.attention`)
    out = Linear 800 -> 219 of the first 20 tokens: the next 20 frames (L2 loss).

All transformers: pre-LayerNorm blocks, 16 heads, hidden 800, MLP 3072 with GELU (FACT). Layer counts are not
given by [QEAN]; the defaults are FACT's (audio 2, motion 2, cross-modal 12). The learnable absolute
position embeddings are [QEAN] Table 2's ablation baseline that Spin Position Embedding replaces;
``learned_positions`` adds them back (default off).

``smoothing_stages`` > 0 (ours, default 0 = [QEAN]) puts a causal low-pass at the output, trained through:
the head's outputs ``x`` become frames by the cascade of ``smoothing_stages`` moving averages of decay
``smoothing_decay`` carried on from the input's last frames,
``y_t = (1 - d)^K x_t - sum_{j=1..K} C(K, j) (-d)^j y_{t-j}``
(:meth:`~skeleton_mamba.tasks.training.causal_smoothing.CausalSmoothing.continued`). Generation keeps one
frame per step, each from a network call that sees a window moved by one frame, so the network's error is
drawn afresh at every frame: at 60 fps it is white noise on the pose, far above the dance's 1-3 Hz, and the
dance trembles. The filter's only state is the last ``K`` frames, which the window holds, so training with
the true past (teacher forcing) trains the filter exactly as generation runs it, and its error reaches the
dance low-passed.
"""

from __future__ import annotations

import dataclasses

import torch
from einops import rearrange
from torch import nn

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.pretrained.mixin import PretrainedMixin
from skeleton_mamba.tasks.motion.music.features import NUM_MUSIC_FEATURES
from skeleton_mamba.tasks.qean.attention import QuaternionRotaryAttention, RotarySelfAttention
from skeleton_mamba.tasks.training.backbone_config import derived_backbone
from skeleton_mamba.tasks.training.causal_smoothing import CausalSmoothing

__all__ = [
    "QEAN",
    "QEANConfig",
    "RotaryTransformer",
    "SkeletonMambaMotionEncoder",
    "TransformerMotionEncoder",
]

MOTION_DIM = 219


@dataclasses.dataclass
class QEANConfig:
    """Sizes of QEAN (defaults: [QEAN] Sec. 4.2; layer counts, MLP width, P: FACT / our choice)."""

    motion_dim: int = MOTION_DIM
    music_dim: int = NUM_MUSIC_FEATURES
    hidden: int = 800
    heads: int = 16
    motion_layers: int = 2
    audio_layers: int = 2
    cross_layers: int = 12
    mlp_dim: int = 3072
    dropout: float = 0.1
    num_periods: int = 4
    conv_kernel: int = 3
    rotary_base: float = 10000.0
    seed_frames: int = 120
    music_frames: int = 240
    predict_frames: int = 20
    learned_positions: bool = False
    smoothing_stages: int = 0
    smoothing_decay: float = 0.5


class _MLP(nn.Sequential):
    def __init__(self, dim: int, mlp_dim: int, dropout: float) -> None:
        super().__init__(nn.Linear(dim, mlp_dim), nn.GELU(), nn.Linear(mlp_dim, dim), nn.Dropout(dropout))


class _Block(nn.Module):
    """Pre-LayerNorm transformer block around ``attention`` (Fig. 4: dropout after attention and MLP)."""

    def __init__(self, attention: nn.Module, dim: int, mlp_dim: int, dropout: float) -> None:
        super().__init__()
        self.norm1 = nn.LayerNorm(dim)
        self.attention = attention
        self.drop = nn.Dropout(dropout)
        self.norm2 = nn.LayerNorm(dim)
        self.mlp = _MLP(dim, mlp_dim, dropout)

    def forward(self, x: torch.Tensor, num_queries: int | None = None) -> torch.Tensor:
        """(B, T, dim) -> (B, T, dim), or only the first ``num_queries`` tokens (QRA blocks)."""
        if num_queries is None:
            x = x + self.drop(self.attention(self.norm1(x)))
        else:
            x = x[:, :num_queries] + self.drop(self.attention(self.norm1(x), num_queries=num_queries))
        return x + self.mlp(self.norm2(x))

    def forward_projected(self, x: torch.Tensor, qkv: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """:meth:`forward` of a self-attention block whose ``attention.project(norm1(x))`` is given."""
        x = x + self.drop(self.attention.attend(*qkv))
        return x + self.mlp(self.norm2(x))


class RotaryTransformer(nn.Module):
    """Encoder of pre-LN blocks with Spin Position Embedding self-attention: (B, T, dim) -> (B, T, dim)."""

    def __init__(self, dim: int, heads: int, layers: int, mlp_dim: int, dropout: float, base: float) -> None:
        super().__init__()
        self.blocks = nn.ModuleList(
            _Block(RotarySelfAttention(dim, heads, dropout, base), dim, mlp_dim, dropout)
            for _ in range(layers)
        )
        self.norm = nn.LayerNorm(dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for block in self.blocks:
            x = block(x)
        return self.norm(x)

    def first_projections(self, x: torch.Tensor, offset: int = 0) -> tuple[torch.Tensor, ...]:
        """The first block's per-token work: (B, T, dim) -> rotated q, k, v (B, heads, T, d), from ``offset``.

        Needs at least one block and an input without learned positions to be reusable across windows.
        """
        return self.blocks[0].attention.project(self.blocks[0].norm1(x), offset)

    def forward_projected(self, x: torch.Tensor, qkv: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """:meth:`forward` given ``first_projections`` of ``x`` (at any offset: scores are relative)."""
        x = self.blocks[0].forward_projected(x, qkv)
        for block in self.blocks[1:]:
            x = block(x)
        return self.norm(x)


class _Embedding(nn.Module):
    """Linear input embedding plus optional learnable absolute positions: (B, T, C) -> (B, T, dim)."""

    def __init__(self, in_dim: int, dim: int, length: int, learned_positions: bool) -> None:
        super().__init__()
        self.linear = nn.Linear(in_dim, dim)
        self.positions = nn.Parameter(torch.randn(length, dim) * 0.02) if learned_positions else None

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.linear(x)
        return y if self.positions is None else y + self.positions[: x.shape[1]]


class TransformerMotionEncoder(nn.Module):
    """f_mot of [QEAN]: (B, T, 219) -> (B, T, hidden)."""

    def __init__(self, config: QEANConfig) -> None:
        super().__init__()
        c = config
        self.embed = _Embedding(c.motion_dim, c.hidden, c.seed_frames, c.learned_positions)
        self.encoder = RotaryTransformer(
            c.hidden, c.heads, c.motion_layers, c.mlp_dim, c.dropout, c.rotary_base
        )

    def forward(self, motion: torch.Tensor) -> torch.Tensor:
        return self.encoder(self.embed(motion))


class SkeletonMambaMotionEncoder(nn.Module):
    """SkeletonMamba as f_mot: (B, T, 219) -> 24 joint tokens (B, T, 24, 12) -> (B, T, hidden).

    A joint token is its rotation matrix (9) and the root translation (3, repeated on every joint so each
    token sees the global position); the backbone's (B, T, 24, D) output is flattened and projected.
    """

    def __init__(self, config: QEANConfig, backbone: SkeletonMambaConfig) -> None:
        super().__init__()
        if config.motion_dim != MOTION_DIM:
            raise ValueError(
                f"the SkeletonMamba encoder reads the 219-d SMPL-24 vector, got {config.motion_dim}"
            )
        backbone = derived_backbone(backbone, "QEAN", skeleton="smpl24", in_channels=12, out_channels=None)
        self.backbone = SkeletonMamba(backbone)
        self.project = nn.Linear(24 * backbone.dim, config.hidden)
        self.norm = nn.LayerNorm(config.hidden)

    def forward(self, motion: torch.Tensor) -> torch.Tensor:
        trans, rot = motion[..., :3], rearrange(motion[..., 3:], "b t (j c) -> b t j c", j=24)
        tokens = torch.cat([rot, trans.unsqueeze(-2).expand(*rot.shape[:-1], 3)], dim=-1)
        return self.norm(self.project(rearrange(self.backbone(tokens), "b t j d -> b t (j d)")))


class QEAN(PretrainedMixin, nn.Module):
    """Music + seed motion -> the next ``predict_frames`` motion frames.

    Args:
        config: sizes (:class:`QEANConfig`).
        backbone: a SkeletonMamba config to use as the motion encoder (``None``: [QEAN]'s transformer).
    """

    pretrained_task = "QEAN: music and seed motion (FACT 219-d) to the next motion frames."
    pretrained_citations = ("QEAN", "EgoMusic", "Mamba-2")

    def __init__(self, config: QEANConfig | None = None, backbone: SkeletonMambaConfig | None = None) -> None:
        super().__init__()
        c = self.config = config or QEANConfig()
        if backbone is None:
            self.motion_encoder: nn.Module = TransformerMotionEncoder(c)
        else:
            self.motion_encoder = SkeletonMambaMotionEncoder(c, backbone)
        self.audio_embed = _Embedding(c.music_dim, c.hidden, c.music_frames, c.learned_positions)
        self.audio_encoder = RotaryTransformer(
            c.hidden, c.heads, c.audio_layers, c.mlp_dim, c.dropout, c.rotary_base
        )
        self.cross_blocks = nn.ModuleList(
            _Block(
                QuaternionRotaryAttention(c.hidden, c.heads, c.num_periods, c.conv_kernel, c.dropout),
                c.hidden,
                c.mlp_dim,
                c.dropout,
            )
            for _ in range(c.cross_layers)
        )
        self.norm = nn.LayerNorm(c.hidden)
        self.head = nn.Linear(c.hidden, c.motion_dim)
        if c.smoothing_stages > c.seed_frames:
            raise ValueError(
                f"smoothing_stages ({c.smoothing_stages}) must not exceed seed_frames ({c.seed_frames})"
            )
        self.smoothing = CausalSmoothing(c.smoothing_stages, c.smoothing_decay)

    def encode_music(self, music: torch.Tensor) -> torch.Tensor:
        """h^z: (B, 240, 35) -> (B, 240, hidden). Depends on the music only (cached by fast generation)."""
        return self.audio_encoder(self.audio_embed(music))

    def encode_motion(self, motion: torch.Tensor) -> torch.Tensor:
        """h^y: (B, 120, 219) -> (B, 120, hidden)."""
        return self.motion_encoder(motion)

    def decode(
        self, h_motion: torch.Tensor, h_music: torch.Tensor, num_outputs: int | None = None
    ) -> torch.Tensor:
        """Cross-modal transformer on ``[h^y ; h^z]`` -> the first ``num_outputs`` frames (B, n, 219).

        The last block computes only the first ``num_outputs`` queries (default ``predict_frames``); every
        earlier block needs all tokens as keys of the next.
        """
        n = self.config.predict_frames if num_outputs is None else num_outputs
        x = torch.cat([h_motion, h_music], dim=1)
        last = len(self.cross_blocks) - 1
        for i, block in enumerate(self.cross_blocks):
            x = block(x, num_queries=n if i == last else None)
        return self.head(self.norm(x[:, :n]))

    def to_frames(self, out: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
        """The head's output (B, n, 219) as frames: the output low-pass carried on from the last frames of
        ``motion`` (B, >= smoothing_stages, 219) when ``smoothing_stages`` > 0, else unchanged ([QEAN])."""
        return self.smoothing.continued(out, motion)

    def forward(
        self, motion: torch.Tensor, music: torch.Tensor, num_outputs: int | None = None
    ) -> torch.Tensor:
        """Seed motion (B, 120, 219) and music (B, 240, 35) -> next frames (B, predict_frames, 219)."""
        out = self.decode(self.encode_motion(motion), self.encode_music(music), num_outputs)
        return self.to_frames(out, motion)
