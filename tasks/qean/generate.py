"""Autoregressive dance generation with QEAN ([QEAN] Sec. 4.2), plain and fast.

Step ``i`` (0-based) sees the last ``seed_frames`` motion frames (the seed, then generated frames) and the
music window ``[i, i + music_frames)`` (aligned at their first frame, FACT's inference), predicts the next
``predict_frames`` frames and keeps only the first. Music past the end of the track is zero-padded.

:func:`generate_plain` runs the whole network every step. :func:`generate_fast` gives the same frames (to
floating-point rounding) with less work, reusing what does not change between steps:

* per-token work is done once per token instead of once per window holding it: the input embedding, the
  first block's LayerNorm and query/key/value projections and their Spin Position Embedding rotation, for
  every music frame of the track (once, before the loop) and every motion frame (the seed's once, then each
  new frame once). Tokens are rotated at their absolute frame index; Spin Position Embedding scores depend
  on position differences only (Eq. 24), so a window attends over them exactly as over tokens rotated at
  ``0 .. window - 1``;
* the rest of the audio encoder depends on the music only: the next ``audio_chunk`` windows are encoded in
  one batched call before the steps that use them;
* only the first prediction is kept, so the last cross-modal block computes one query row instead of
  ``predict_frames`` (attention, MLP and head), which is exact since rows do not interact after it;
* no autograd graph is recorded.

Every encoder attends bidirectionally within its sliding window ([QEAN]'s design), so from the first
attention on, the hidden states of all three transformers change for every token when the window moves one
frame; a key/value cache of deeper layers would change the model, and is not used. With learned absolute
positions (the ablation baseline) or the SkeletonMamba motion encoder the per-token reuse does not apply
(embeddings depend on the position in the window / no first projection), and that encoder runs per window.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn
from tqdm import tqdm

from skeleton_mamba.tasks.qean.model import QEAN, RotaryTransformer, TransformerMotionEncoder

__all__ = ["generate_fast", "generate_plain", "pad_music"]


def pad_music(music: torch.Tensor, num_frames: int, window: int) -> torch.Tensor:
    """Zero-pad (or cut) music (B, T, C) to the ``num_frames + window - 1`` frames the steps read."""
    need = num_frames + window - 1
    if music.shape[1] >= need:
        return music[:, :need]
    return F.pad(music, (0, 0, 0, need - music.shape[1]))


def _check(model: QEAN, seed: torch.Tensor, music: torch.Tensor) -> None:
    c = model.config
    if seed.ndim != 3 or seed.shape[1] < c.seed_frames or seed.shape[2] != c.motion_dim:
        raise ValueError(f"seed must be (B, >= {c.seed_frames}, {c.motion_dim}), got {tuple(seed.shape)}")
    if music.ndim != 3 or music.shape[0] != seed.shape[0] or music.shape[2] != c.music_dim:
        raise ValueError(f"music must be (B={seed.shape[0]}, T, {c.music_dim}), got {tuple(music.shape)}")


@torch.no_grad()
def generate_plain(
    model: QEAN, seed: torch.Tensor, music: torch.Tensor, num_frames: int = 1200, progress: bool = False
) -> torch.Tensor:
    """Reference loop: the full network per step.

    Args:
        model: a QEAN (put in eval mode by the caller for deterministic output).
        seed: (B, >= seed_frames, 219) seed motion; its last ``seed_frames`` frames are used.
        music: (B, T, 35) music features of the whole track, frame 0 aligned with the seed's first frame.
        num_frames: frames to generate (1200 = 20 s at 60 fps).
        progress: show a tqdm bar.

    Returns:
        (B, num_frames, 219) generated frames (seed excluded).
    """
    _check(model, seed, music)
    c = model.config
    seed = seed[:, -c.seed_frames :]
    music = pad_music(music, num_frames, c.music_frames)
    motion = seed
    out = []
    for i in tqdm(range(num_frames), desc="QEAN (plain)", disable=not progress):
        frame = model(motion[:, -c.seed_frames :], music[:, i : i + c.music_frames])[:, :1]
        out.append(frame)
        motion = torch.cat([motion[:, 1:], frame], dim=1)
    return torch.cat(out, dim=1)


def _per_token_reuse(embed: nn.Module, encoder: RotaryTransformer) -> bool:
    """Whether embedding and first projections are per token (no learned positions, at least one block)."""
    return getattr(embed, "positions", True) is None and len(encoder.blocks) > 0


def _windows(x: torch.Tensor, dim: int, start: int, count: int, size: int) -> torch.Tensor:
    """``count`` windows ``[start + w, start + w + size)`` along ``dim``, stacked into the batch.

    (B, ..., T, ...) -> (B * count, ..., size, ...), windows of one batch element consecutive.
    """
    x = x.narrow(dim, start, count + size - 1).unfold(dim, size, 1)  # (B, .., count, .., size)
    x = x.movedim(-1, dim + 1).movedim(dim, 1)  # (B, count, ..., size, ...)
    return x.reshape(x.shape[0] * count, *x.shape[2:])


class _MotionTokens:
    """Motion frames embedded and projected by the first motion block once each, at absolute positions."""

    def __init__(self, model: QEAN, seed: torch.Tensor, num_frames: int) -> None:
        encoder = model.motion_encoder
        self.embed, self.encoder, self.window = encoder.embed, encoder.encoder, seed.shape[1]
        h = self.embed(seed)
        parts = [h, *self.encoder.first_projections(h, 0)]
        # buffers for the seed and every generated frame: h (B, S + N, D); q, k, v (B, heads, S + N, d)
        dims = (1, 2, 2, 2)
        self.buffers = [
            torch.cat([p, p.new_empty(*p.shape[:d], num_frames, *p.shape[d + 1 :])], dim=d)
            for p, d in zip(parts, dims, strict=True)
        ]
        self.dims = dims

    def append(self, frame: torch.Tensor, position: int) -> None:
        """Embed and project one new frame (B, 1, 219) at absolute ``position``."""
        h = self.embed(frame)
        for buf, part, d in zip(self.buffers, [h, *self.encoder.first_projections(h, position)], self.dims):
            buf.narrow(d, position, 1).copy_(part)

    def encode(self, start: int) -> torch.Tensor:
        """h^y of the window ``[start, start + S)``: (B, S, hidden)."""
        h, q, k, v = (buf.narrow(d, start, self.window) for buf, d in zip(self.buffers, self.dims))
        return self.encoder.forward_projected(h, (q, k, v))


@torch.no_grad()
def generate_fast(
    model: QEAN,
    seed: torch.Tensor,
    music: torch.Tensor,
    num_frames: int = 1200,
    audio_chunk: int = 32,
    progress: bool = False,
) -> torch.Tensor:
    """The same frames as :func:`generate_plain` with the reuse of the module docstring.

    Args:
        model: as :func:`generate_plain`.
        seed: as :func:`generate_plain`.
        music: as :func:`generate_plain`.
        num_frames: as :func:`generate_plain`.
        audio_chunk: music windows encoded per batched audio-encoder call.
        progress: as :func:`generate_plain`.
    """
    _check(model, seed, music)
    if audio_chunk < 1:
        raise ValueError(f"audio_chunk must be >= 1, got {audio_chunk}")
    c = model.config
    b, window = seed.shape[0], c.music_frames
    motion = seed[:, -c.seed_frames :]
    music = pad_music(music, num_frames, window)
    reuse_music = _per_token_reuse(model.audio_embed, model.audio_encoder)
    if reuse_music:  # the whole track once: h (B, L, D), q, k, v (B, heads, L, d) at absolute positions
        h_music = model.audio_embed(music)
        music_tokens = (h_music, *model.audio_encoder.first_projections(h_music, 0))
    motion_tokens = None
    if isinstance(model.motion_encoder, TransformerMotionEncoder) and _per_token_reuse(
        model.motion_encoder.embed, model.motion_encoder.encoder
    ):
        motion_tokens = _MotionTokens(model, motion, num_frames)
    out = []
    encoded = None
    recent = motion  # the last frames, from which the output low-pass carries on
    for i in tqdm(range(num_frames), desc="QEAN (fast)", disable=not progress):
        j = i % audio_chunk
        if j == 0:
            count = min(audio_chunk, num_frames - i)
            if reuse_music:
                h, q, k, v = (_windows(x, d, i, count, window) for x, d in zip(music_tokens, (1, 2, 2, 2)))
                encoded = model.audio_encoder.forward_projected(h, (q, k, v))
            else:
                encoded = model.encode_music(_windows(music, 1, i, count, window))
            encoded = encoded.reshape(b, count, window, -1)
        if motion_tokens is None:
            h_motion = model.encode_motion(motion)
        else:
            h_motion = motion_tokens.encode(i)
        frame = model.to_frames(model.decode(h_motion, encoded[:, j], num_outputs=1), recent)
        out.append(frame)
        recent = torch.cat([recent[:, 1:], frame], dim=1)
        if motion_tokens is None:
            motion = torch.cat([motion[:, 1:], frame], dim=1)
        elif i + 1 < num_frames:
            motion_tokens.append(frame, c.seed_frames + i)
    return torch.cat(out, dim=1)
