"""The text-to-motion denoiser: Skeleton Mamba over HumanML3D features as joints ([EgoMusic] supp. 8.2).

The 263-d frame is split into 22 joint tokens of :data:`JOINT_CHANNELS` (13) channels each, so the
backbone's Human Tokenizer (HUMANML3D22 groups) sees a skeleton:

=========  ===================================================  ====================================
channels   joint 0 (root)                                       joints 1..21
=========  ===================================================  ====================================
0:4        root rotation velocity, XZ velocity, height          ric position (3) + rot6d[0] (1)
4:9        zero                                                 rot6d[1:6]
9:12       root local velocity                                  local velocity
12         zero                                                 foot contact (joints 7, 10, 8, 11)
=========  ===================================================  ====================================

(joints 1..21 hold ric 0:3 and their 6D rotation 3:9.) Every feature has exactly one slot, so
:func:`features_to_tokens` and :func:`tokens_to_features` are exact inverses.

Conditioning: the timestep (sinusoidal embedding + MLP) is concatenated to every joint token's input
channels and also forms the first cross-attention token; the caption's token embeddings follow it
(projected to ``text_dim``). The unconditional prediction used by classifier-free guidance masks out
every text token, leaving the timestep token. The denoiser predicts x0 (MDM), preconditioned
with the per-feature statistics of the normalised training features (``mu + c_skip (x_t - a mu) + c_out F``
with the backbone's output F: :mod:`skeleton_mamba.tasks.training.diffusion.parameterisation`).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.pretrained.mixin import PretrainedMixin
from skeleton_mamba.tasks.motion.body.statistics import channel_statistics
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FEATURE_DIM, NUM_JOINTS
from skeleton_mamba.tasks.training.backbone_config import derived_backbone
from skeleton_mamba.tasks.training.diffusion.embedding import sinusoidal_embedding
from skeleton_mamba.tasks.training.diffusion.parameterisation import SkipX0
from skeleton_mamba.tasks.training.diffusion.temporal_prior import (
    TemporalPriorSkipX0,
    power_spectrum,
)

__all__ = [
    "JOINT_CHANNELS",
    "TextCondition",
    "feature_index",
    "features_to_tokens",
    "tokens_to_features",
    "timestep_embedding",
    "TextToMotionDenoiser",
]

JOINT_CHANNELS = 13
PRIOR_SEGMENT_FRAMES = 64  # frames of the stretches the temporal prior's spectrum is measured on (3.2 s)
_CONTACT_JOINTS = (7, 10, 8, 11)  # order of the feature slice [259:263]


def feature_index() -> torch.Tensor:
    """(22, 13) long: the feature index of each joint-token channel, ``263`` for an empty slot."""
    index = torch.full((NUM_JOINTS, JOINT_CHANNELS), FEATURE_DIM, dtype=torch.long)
    index[0, 0:4] = torch.arange(0, 4)
    for j in range(1, NUM_JOINTS):
        index[j, 0:3] = 4 + 3 * (j - 1) + torch.arange(3)
        index[j, 3:9] = 67 + 6 * (j - 1) + torch.arange(6)
    for j in range(NUM_JOINTS):
        index[j, 9:12] = 193 + 3 * j + torch.arange(3)
    for k, j in enumerate(_CONTACT_JOINTS):
        index[j, 12] = 259 + k
    return index


_INDEX = feature_index()


def features_to_tokens(features: torch.Tensor) -> torch.Tensor:
    """(..., T, 263) -> (..., T, 22, 13) joint tokens (zeros in empty slots)."""
    padded = torch.cat([features, features.new_zeros(*features.shape[:-1], 1)], dim=-1)
    return padded[..., _INDEX.to(features.device)]


def tokens_to_features(tokens: torch.Tensor) -> torch.Tensor:
    """(..., T, 22, 13) -> (..., T, 263): each feature read from its slot (empty slots ignored)."""
    flat_index = _INDEX.to(tokens.device).flatten()
    used = flat_index < FEATURE_DIM
    flat = tokens.flatten(-2)[..., used]
    out = tokens.new_zeros(*tokens.shape[:-2], FEATURE_DIM)
    return out.index_copy(-1, flat_index[used], flat)


TIME_EMBEDDING_ORDER = "cos_sin"
"""The text-to-motion denoisers' timestep embedding layout (guided-diffusion's ``[cos, sin]``) of
:func:`~skeleton_mamba.tasks.training.diffusion.sinusoidal_embedding`, kept so checkpoints keep their
outputs."""


def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """(B,) timesteps -> (B, dim) ``[cos(t f_k), sin(t f_k)]`` (:data:`TIME_EMBEDDING_ORDER`)."""
    return sinusoidal_embedding(t, dim, order=TIME_EMBEDDING_ORDER)


@dataclass
class TextCondition:
    """Caption token embeddings (B, S, D) and their mask (B, S) bool (True = real token)."""

    tokens: torch.Tensor
    mask: torch.Tensor

    def pooled(self) -> torch.Tensor:
        """(B, D) the mean of the real tokens' embeddings (MiniLM's sentence embedding before its
        normalisation); zeros for the null caption."""
        weights = self.mask.to(self.tokens.device, self.tokens.dtype)[..., None]
        return (self.tokens * weights).sum(1) / weights.sum(1).clamp(min=1.0)

    def null(self) -> TextCondition:
        """The null condition of this batch: all padding (no caption token), of the same shape.

        Both text-to-motion denoisers read an all-padding caption exactly as no caption (the
        cross-attention sees only the time token; the transformer's pooled text is zero), so one call
        on the doubled batch ``[cond; null]`` gives the conditional and the unconditional prediction.
        """
        return TextCondition(torch.zeros_like(self.tokens), torch.zeros_like(self.mask))


class LengthMaskedDenoiser:
    """A text-to-motion denoiser at fixed frame masks, as the samplers call it: ``(x_t, t, cond) -> x0``.

    ``model(x_t, t, cond, mask)`` is either denoiser of this package; ``mask`` (B, T) bool marks valid
    frames. It implements :class:`~skeleton_mamba.tasks.training.diffusion.NullConditioned` (the null caption
    :meth:`TextCondition.null`); on the doubled batch of classifier-free guidance the mask repeats.
    """

    def __init__(self, model: nn.Module, mask: torch.Tensor) -> None:
        self.model = model
        self.mask = mask

    def __call__(self, x_t: torch.Tensor, t: torch.Tensor, cond: TextCondition | None) -> torch.Tensor:
        repeats = x_t.shape[0] // self.mask.shape[0]
        mask = self.mask if repeats == 1 else self.mask.repeat(repeats, 1)
        return self.model(x_t, t, cond, mask)

    @staticmethod
    def null_condition(cond: TextCondition) -> TextCondition:
        return cond.null()


class TextToMotionDenoiser(PretrainedMixin, nn.Module):
    """x0 prediction ``(x_t (B, T, 263), t (B,), cond, mask (B, T)) -> x0_hat (B, T, 263)``.

    Args:
        backbone: Skeleton Mamba configuration; ``skeleton``, ``in_channels``, ``out_channels`` and
            ``context_dim`` are set here (humanml3d22, 13 + ``time_channels``, 13, ``text_dim``).
        text_dim: width of the caption token embeddings (384 MiniLM, 512 CLIP ViT-B/32).
        time_channels: timestep channels appended to every joint token.
        time_embedding_dim: sinusoidal embedding size of the timestep.
        diffusion_steps: T of the noise schedule (scales the skip connection from x_t,
            :mod:`skeleton_mamba.tasks.training.diffusion.parameterisation`).
        temporal_prior: precondition with a Gaussian process over time (:meth:`set_data_statistics`).
        pooled_text: also add the caption's pooled embedding (the mean of its token embeddings: the
            sentence embedding of MiniLM) to the timestep embedding, as [MDM] sums text and timestep, so the
            caption reaches every joint token's input as well as the cross-attention.
    """

    pretrained_task = "Text-to-motion x0 denoiser: HumanML3D 263-d features from caption token embeddings."
    pretrained_citations = ("EgoMusic", "Mamba-2", "MDM")

    def __init__(
        self,
        backbone: SkeletonMambaConfig,
        text_dim: int,
        time_channels: int = 16,
        time_embedding_dim: int = 128,
        diffusion_steps: int = 1000,
        temporal_prior: bool = False,
        pooled_text: bool = False,
    ) -> None:
        super().__init__()
        config = derived_backbone(
            backbone,
            "the text-to-motion denoiser",
            skeleton="humanml3d22",
            in_channels=JOINT_CHANNELS + time_channels,
            out_channels=JOINT_CHANNELS,
            context_dim=text_dim,
        )
        self.backbone = SkeletonMamba(config)
        self.time_embedding_dim = time_embedding_dim
        width = time_embedding_dim
        self.time_mlp = nn.Sequential(nn.Linear(width, width), nn.SiLU(), nn.Linear(width, width))
        self.time_to_channels = nn.Linear(time_embedding_dim, time_channels)
        self.time_to_token = nn.Linear(time_embedding_dim, text_dim)
        self.text_proj = nn.Linear(text_dim, text_dim)
        self.pooled_text = nn.Linear(text_dim, time_embedding_dim) if pooled_text else None
        self.temporal_prior = temporal_prior
        if temporal_prior:
            self.skip_x0 = TemporalPriorSkipX0(diffusion_steps, FEATURE_DIM, segment=PRIOR_SEGMENT_FRAMES)
        else:
            self.skip_x0 = SkipX0(diffusion_steps, channels=(FEATURE_DIM,))

    def set_data_statistics(self, features: torch.Tensor, lengths: torch.Tensor | None = None) -> None:
        """Per-feature mean and std of normalised training features (N, 263) for the preconditioning (the
        group-wise normalisation of HumanML3D leaves them off 0 and 1) and, with ``temporal_prior``, their
        power spectrum over time, on the clips of ``lengths`` (K,) frames that ``features`` joins (None:
        one sequence)."""
        features = features.reshape(-1, FEATURE_DIM)
        self.skip_x0.set_statistics(*channel_statistics(features, name="features"))
        if self.temporal_prior:
            clips = features.split(lengths.tolist()) if lengths is not None else (features,)
            spectrum = power_spectrum(clips, PRIOR_SEGMENT_FRAMES, self.skip_x0.data_mean)
            self.skip_x0.set_spectrum(spectrum)

    def forward(
        self,
        x_t: torch.Tensor,
        t: torch.Tensor,
        cond: TextCondition | None = None,
        mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        b, frames, _ = x_t.shape
        emb = self.time_mlp(timestep_embedding(t, self.time_embedding_dim).to(x_t.dtype))  # (B, E)
        if self.pooled_text is not None and cond is not None:
            has_caption = cond.mask.to(x_t.device).any(1, keepdim=True).to(x_t.dtype)  # (B, 1)
            emb = emb + self.pooled_text(cond.pooled().to(x_t.dtype)) * has_caption  # null: as no caption
        channels = self.time_to_channels(emb)[:, None, None, :].expand(b, frames, NUM_JOINTS, -1)
        x_in = self.skip_x0.network_input(x_t, t)
        tokens = torch.cat([features_to_tokens(x_in), channels], dim=-1)  # (B, T, 22, 13 + C_t)
        time_token = self.time_to_token(emb)[:, None, :]  # (B, 1, D)
        if cond is None:
            context, context_mask = time_token, torch.ones(b, 1, dtype=torch.bool, device=x_t.device)
        else:
            context = torch.cat([time_token, self.text_proj(cond.tokens.to(x_t.dtype))], dim=1)
            ones = torch.ones(b, 1, dtype=torch.bool, device=x_t.device)
            context_mask = torch.cat([ones, cond.mask.to(x_t.device)], dim=1)
        out = self.backbone(tokens, mask=mask, context=context, context_mask=context_mask)
        x0 = self.skip_x0(x_t, tokens_to_features(out), t, mask)
        if mask is not None:
            x0 = x0 * mask[..., None].to(x0.dtype)
        return x0
