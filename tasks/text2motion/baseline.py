"""An MDM-style transformer denoiser: the baseline the Skeleton Mamba denoiser is timed against.

As MDM's default ``trans_enc`` (``GuyTevet/motion-diffusion-model model/mdm.py``): each frame's 263-d
features -> Linear -> ``latent`` width; the timestep (sinusoidal -> MLP) plus the projected pooled caption
embedding form one token prepended to the frames; sinusoidal positions (MDM's interleaved ones:
:func:`~skeleton_mamba.tasks.training.diffusion.embedding.sinusoidal_embedding`); a post-norm
``nn.TransformerEncoder`` (GELU, dropout 0.1, feed-forward ``ff_ratio * latent``); the frame outputs ->
Linear -> x0 (263). MDM pools CLIP's sentence embedding; here the caption tokens (B, S, D) of our text
encoder are mean-pooled over the mask. The unconditional prediction zeroes the caption embedding (MDM
``mask_cond``). Padded frames are excluded by ``src_key_padding_mask``.

:func:`width_for_parameters` picks the latent width that gives a target parameter count, so the two
denoisers are compared at equal size. The call signature is :class:`~.model.TextToMotionDenoiser`'s,
so the shared diffusion samplers run either.
"""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba.tasks.motion.formats.humanml3d_features import FEATURE_DIM
from skeleton_mamba.tasks.text2motion.model import TextCondition, timestep_embedding
from skeleton_mamba.tasks.training.diffusion.embedding import sinusoidal_embedding

__all__ = ["TransformerDenoiser", "width_for_parameters"]


class TransformerDenoiser(nn.Module):
    """x0 prediction ``(x_t (B, T, 263), t (B,), cond, mask (B, T)) -> x0_hat (B, T, 263)``.

    Args:
        text_dim: width of the caption token embeddings (384 MiniLM, 512 CLIP).
        latent: transformer width (MDM 512; must be even and divisible by ``heads``).
        layers: encoder layers (MDM 8).
        heads: attention heads (MDM 4).
        ff_ratio: feed-forward width / latent (MDM 1024 / 512 = 2).
        dropout: dropout (MDM 0.1).
    """

    def __init__(
        self,
        text_dim: int,
        latent: int = 512,
        layers: int = 8,
        heads: int = 4,
        ff_ratio: float = 2.0,
        dropout: float = 0.1,
    ) -> None:
        super().__init__()
        if latent % 2 or latent % heads:
            raise ValueError(f"latent ({latent}) must be even and divisible by heads ({heads})")
        self.latent = latent
        self.input_process = nn.Linear(FEATURE_DIM, latent)
        self.time_mlp = nn.Sequential(nn.Linear(latent, latent), nn.SiLU(), nn.Linear(latent, latent))
        self.embed_text = nn.Linear(text_dim, latent)
        layer = nn.TransformerEncoderLayer(
            latent, heads, int(ff_ratio * latent), dropout, activation="gelu", batch_first=True
        )
        self.encoder = nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)
        self.output_process = nn.Linear(latent, FEATURE_DIM)

    def forward(
        self,
        x_t: torch.Tensor,
        t: torch.Tensor,
        cond: TextCondition | None = None,
        mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        b, frames, _ = x_t.shape
        token = self.time_mlp(timestep_embedding(t, self.latent).to(x_t.dtype))  # (B, L)
        if cond is not None:
            weights = cond.mask.to(x_t.dtype)[..., None]
            pooled = (cond.tokens.to(x_t.dtype) * weights).sum(1) / weights.sum(1).clamp(min=1)
            token = token + self.embed_text(pooled)  # an all-masked caption pools to zero
        else:
            token = token + self.embed_text(x_t.new_zeros(b, self.embed_text.in_features))
        # MDM's PositionalEncoding (sines in the even channels, cosines in the odd ones), bit for bit
        steps = torch.arange(frames, device=x_t.device)
        positions = sinusoidal_embedding(steps, self.latent, order="interleaved")
        frames_in = self.input_process(x_t) + positions
        sequence = torch.cat([token[:, None], frames_in], dim=1)  # (B, 1 + T, L)
        padding = None
        if mask is not None:
            padding = torch.cat([mask.new_zeros(b, 1), ~mask], dim=1)  # True = ignore
        out = self.output_process(self.encoder(sequence, src_key_padding_mask=padding)[:, 1:])
        if mask is not None:
            out = out * mask[..., None].to(out.dtype)
        return out


def width_for_parameters(
    target: int, text_dim: int, layers: int = 8, heads: int = 4, ff_ratio: float = 2.0
) -> int:
    """The latent width (a multiple of ``2 * heads``) whose :class:`TransformerDenoiser` has the parameter
    count nearest to ``target`` (models built on the meta device and counted; the count grows with width)."""
    step = 2 * heads

    def count(units: int) -> int:
        with torch.device("meta"):
            model = TransformerDenoiser(text_dim, units * step, layers, heads, ff_ratio)
        return sum(p.numel() for p in model.parameters())

    low, high = 1, 2
    while count(high) < target:
        low, high = high, high * 2
    while high - low > 1:  # count(low) < target <= count(high), or low = 1
        middle = (low + high) // 2
        low, high = (middle, high) if count(middle) < target else (low, middle)
    best = min((low, high), key=lambda units: abs(count(units) - target))
    return best * step
