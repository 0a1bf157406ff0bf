"""Autoregressive dance generation with QEAN (seed 003 section 4.2), plain and fast.

Step ``i`` (0-based) sees the last ``seed_frames`` motion frames (the seed, then generated frames) and the
music window ``[i, i + music_frames)`` (aligned at their first frame, FACT's inference), predicts the next
``predict_frames`` frames and keeps only the first. Music past the end of the track is zero-padded.

:func:`generate_plain` runs the whole network every step. :func:`generate_fast` gives the same frames with
less work, reusing what does not change between steps:

* the audio encoder depends on the music only, so its outputs for the next ``audio_chunk`` windows are
  computed in one batched call and reused by those steps (no recomputation per step, better batching);
* only the first prediction is kept, so the last cross-modal block computes one query row instead of
  ``predict_frames`` (attention, MLP and head), which is exact since rows do not interact after it;
* the rotary tables are cached on the attention modules, and no autograd graph is recorded.

Every encoder attends bidirectionally within its sliding window (the seed's design), so the hidden states of
the motion and cross-modal transformers change for every token when the window moves one frame; a
key/value cache of earlier steps would change the model, and is not used.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from tqdm import tqdm

from skeleton_mamba.tasks.qean.model import QEAN

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


@torch.no_grad()
def generate_fast(
    model: QEAN,
    seed: torch.Tensor,
    music: torch.Tensor,
    num_frames: int = 1200,
    audio_chunk: int = 32,
    progress: bool = False,
) -> torch.Tensor:
    """The same frames as :func:`generate_plain`, reusing audio encodings and computing one output row.

    Args:
        model, seed, music, num_frames, progress: as :func:`generate_plain`.
        audio_chunk: music windows encoded per batched audio-encoder call.
    """
    _check(model, seed, music)
    if audio_chunk < 1:
        raise ValueError(f"audio_chunk must be >= 1, got {audio_chunk}")
    c = model.config
    b = seed.shape[0]
    motion = seed[:, -c.seed_frames :]
    music = pad_music(music, num_frames, c.music_frames)
    out = []
    encoded = None
    for i in tqdm(range(num_frames), desc="QEAN (fast)", disable=not progress):
        j = i % audio_chunk
        if j == 0:
            count = min(audio_chunk, num_frames - i)
            # windows [i + w, i + w + music_frames) for w < count: (B, count, music_frames, 35)
            windows = music[:, i : i + count + c.music_frames - 1].unfold(1, c.music_frames, 1)
            windows = windows.permute(0, 1, 3, 2).reshape(b * count, c.music_frames, c.music_dim)
            encoded = model.encode_music(windows).reshape(b, count, c.music_frames, -1)
        frame = model.decode(model.encode_motion(motion), encoded[:, j], num_outputs=1)
        out.append(frame)
        motion = torch.cat([motion[:, 1:], frame], dim=1)
    return torch.cat(out, dim=1)
