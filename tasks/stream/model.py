"""A causal music-to-dance network on Skeleton Mamba that runs frame by frame. Pure torch.

Pose frame t is predicted from the poses before it and the music up to frame t (teacher forcing at
training time, as QEAN [QEAN] trains its autoregressive decoder; its own outputs at inference)::

    prev_t  = pose_{t-1} joint tokens (24, 12), zeros at t = 0 (the start token)
    music_t = normalised causal music features of frame t (34,), copied onto every joint
    pose_t  = smoothing(SkeletonMamba_causal([prev_t | music_t]))_t    (B, T, 24, 46) -> (B, T, 24, 12)

A joint token is the joint's local rotation matrix (9, row-major) and the root position (3, repeated
on every joint), the per-joint form of the 219-d [QEAN] / [FACT] vector
(``tasks.qean.representation``). The music is a per-frame input, not a cross-attention context, so
nothing can attend to future music: the network is causal end to end, and :meth:`step` (one frame,
constant memory) equals :meth:`forward` (a whole sequence). ``smoothing`` is the causal low-pass of
:mod:`~skeleton_mamba.tasks.training.causal_smoothing` (trained through; off with 0 stages), its stages'
values part of the stream's :class:`DancerState`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from einops import rearrange, repeat
from torch import nn

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.pretrained.mixin import PretrainedMixin
from skeleton_mamba.runtime.streaming import StreamState
from skeleton_mamba.tasks.motion.body.statistics import channel_statistics
from skeleton_mamba.tasks.motion.formats.fact_features import (
    features_to_joints,
    features_to_smpl,
    motion_to_features,
)
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.stream.features import FPS, NUM_FEATURES
from skeleton_mamba.tasks.training.backbone_config import derived_backbone
from skeleton_mamba.tasks.training.causal_smoothing import CausalSmoothing

__all__ = [
    "POSE_CHANNELS",
    "DancerState",
    "StreamDancer",
    "motion_to_tokens",
    "teacher_forcing_inputs",
    "tokens_to_features",
    "tokens_to_motion",
]

POSE_CHANNELS = 12  # rotation matrix (9) + root position (3) per joint


def motion_to_tokens(motion: MotionData, fps: float = FPS) -> torch.Tensor:
    """SMPL parameters -> (T, 24, 12) float32 joint tokens at ``fps`` (resampled when needed)."""
    features = motion_to_features(motion, fps)  # (T, 219) = [root (3) | 24 x rotation (9)]
    rot = rearrange(features[:, 3:], "t (j c) -> t j c", j=24)
    return torch.cat([rot, repeat(features[:, :3], "t c -> t j c", j=24)], dim=-1)


def tokens_to_features(tokens: torch.Tensor) -> torch.Tensor:
    """(..., 24, 12) joint tokens -> the (..., 219) vector; the root is the mean of the joints' copies."""
    root = tokens[..., 9:].mean(dim=-2)
    return torch.cat([root, tokens[..., :9].flatten(-2)], dim=-1)


def tokens_to_motion(tokens: torch.Tensor, fps: float = FPS) -> MotionData:
    """(T, 24, 12) predicted tokens -> :class:`MotionData` (rotations projected to the nearest rotation)."""
    features = tokens_to_features(tokens.detach().cpu().double())
    poses, root = features_to_smpl(features)
    return MotionData(
        fps=fps,
        skeleton="smpl24",
        poses=poses.numpy().astype(np.float32),
        trans=root.numpy(),
        scaling=1.0,
        joints=features_to_joints(features).numpy().astype(np.float32),
    )


def teacher_forcing_inputs(motion: torch.Tensor) -> torch.Tensor:
    """Target poses (B, T, 24, 12) -> previous poses (B, T, 24, 12): the start token, then pose t - 1."""
    return torch.cat([torch.zeros_like(motion[:, :1]), motion[:, :-1]], dim=1)


@dataclass
class DancerState(StreamState):
    """A stream's state: the backbone's (:class:`~skeleton_mamba.runtime.streaming.StreamState`, updated in
    place), ``smoothing``, the output low-pass's stages (stages, B, 24, 12) (None without one), and
    ``started`` (False until the first frame, which sets every stage to its value). Its size never changes."""

    smoothing: torch.Tensor | None = None
    started: bool = False

    @property
    def nbytes(self) -> int:
        extra = 0 if self.smoothing is None else self.smoothing.numel() * self.smoothing.element_size()
        return super().nbytes + extra

    def reset(self) -> None:
        super().reset()
        self.started = False
        if self.smoothing is not None:
            self.smoothing.zero_()


class StreamDancer(PretrainedMixin, nn.Module):
    """Causal Skeleton Mamba from previous pose and music to the next pose.

    Args:
        backbone: the backbone size (``skeleton``, ``in_channels``, ``out_channels``, ``causal`` and
            ``context_dim`` are set here).
        music_dim: music features per frame (:data:`~skeleton_mamba.tasks.stream.features.NUM_FEATURES`).
        smoothing_stages: moving averages of the output low-pass (:class:`.CausalSmoothing`; 0: none).
        smoothing_decay: their decay.
    """

    pretrained_task = (
        "Live music-to-dance: a causal Skeleton Mamba from previous pose and music to the next pose."
    )
    pretrained_citations = ("EgoMusic", "Mamba-2")

    def __init__(
        self,
        backbone: SkeletonMambaConfig | None = None,
        music_dim: int = NUM_FEATURES,
        smoothing_stages: int = 0,
        smoothing_decay: float = 0.6,
    ) -> None:
        super().__init__()
        cfg = derived_backbone(
            backbone,
            "the streaming dancer",
            skeleton="smpl24",
            in_channels=POSE_CHANNELS + music_dim,
            out_channels=POSE_CHANNELS,
            causal=True,
            context_dim=None,
        )
        self.music_dim = music_dim
        self.backbone = SkeletonMamba(cfg)
        self.smoothing = CausalSmoothing(smoothing_stages, smoothing_decay)
        # Music feature statistics of the training set (set by the Lightning module before training).
        self.register_buffer("music_mean", torch.zeros(music_dim))
        self.register_buffer("music_std", torch.ones(music_dim))

    def set_music_statistics(self, music: torch.Tensor) -> None:
        """Per-feature mean and standard deviation (floored at 1e-3) of training music (N, music_dim)."""
        mean, std = channel_statistics(music, min_std=1e-3, name="music")
        self.music_mean.copy_(mean)
        self.music_std.copy_(std)

    def _inputs(self, prev: torch.Tensor, music: torch.Tensor) -> torch.Tensor:
        """(..., 24, 12) previous poses and (..., music_dim) music -> (..., 24, 12 + music_dim)."""
        if music.shape[-1] != self.music_dim:
            raise ValueError(f"expected {self.music_dim} music features per frame, got {music.shape[-1]}")
        music = (music - self.music_mean) / self.music_std
        music = music.unsqueeze(-2).expand(*prev.shape[:-1], self.music_dim)
        return torch.cat([prev, music.to(prev.dtype)], dim=-1)

    def forward(self, prev: torch.Tensor, music: torch.Tensor) -> torch.Tensor:
        """Previous poses (B, T, 24, 12) and music (B, T, music_dim) -> poses (B, T, 24, 12)."""
        return self.smoothing.sequence(self.backbone(self._inputs(prev, music)))

    def init_state(self, batch: int = 1) -> DancerState:
        """Zero recurrent state for ``batch`` streams."""
        state = DancerState(**vars(self.backbone.init_state(batch)))
        if self.smoothing.enabled:
            weight = next(self.parameters())
            shape = (self.smoothing.stages, batch, self.backbone.skeleton.num_joints, POSE_CHANNELS)
            state.smoothing = torch.zeros(shape, dtype=weight.dtype, device=weight.device)
        return state

    def step(
        self,
        prev: torch.Tensor,
        music: torch.Tensor,
        state: DancerState,
        backbone_step: Callable | None = None,
    ) -> tuple[torch.Tensor, DancerState]:
        """One frame: previous pose (B, 24, 12) and music (B, music_dim) -> pose (B, 24, 12).

        ``backbone_step``: the backbone's step function (default ``self.backbone.step``; e.g. its
        :meth:`~skeleton_mamba.SkeletonMamba.compile_step`).
        """
        out, state = (backbone_step or self.backbone.step)(self._inputs(prev, music), state)
        if not self.smoothing.enabled:
            return out, state
        pose, state.smoothing = self.smoothing.step(out, state.smoothing, state.started)
        state.started = True
        return pose, state
