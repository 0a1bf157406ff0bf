"""Dance generation with a trained EMM: one window, or long-form by stitched windows, and decoding.

Sampling goes through the shared entry point :func:`~skeleton_mamba.tasks.training.diffusion.sample`
(DDIM, EDGE: 50 steps, eta 1; or ancestral DDPM, the original code, 1000 steps) with classifier-free guidance
(``guidance_weight``) and the head guidance G_head when head targets are given (:mod:`.guidance`);
long tracks through :func:`~skeleton_mamba.tasks.training.diffusion.sample_long`. With ``compile=True`` the
denoiser runs compiled with its weights frozen (:func:`skeleton_mamba.compiling.compile_for_inference`).
"""

from __future__ import annotations

import numpy as np
import torch

from skeleton_mamba.compiling import compile_for_inference
from skeleton_mamba.tasks.egodance.guidance import HeadGuidance
from skeleton_mamba.tasks.egodance.model import EMM
from skeleton_mamba.tasks.egodance.representation import (
    NUM_CHANNELS,
    NUM_JOINTS,
    ROOT,
    decode_motion,
    motion_joints,
)
from skeleton_mamba.tasks.motion.motion_file import MotionData
from skeleton_mamba.tasks.motion.rotations import matrix_to_axis_angle
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, sample, sample_long
from skeleton_mamba.tasks.training.diffusion.stitching import split_windows, window_starts

__all__ = ["CompiledDenoiser", "sample_dance", "sample_long_dance", "tokens_to_motion", "root_xz_mask"]


class CompiledDenoiser:
    """A denoiser's call ``(x_t, t, context) -> x0`` (an EMM's) compiled for inference, weights frozen.

    A :class:`~skeleton_mamba.tasks.training.diffusion.samplers.NullConditioned` denoiser like the model, so
    classifier-free guidance stays one call on the doubled batch. The first call compiles (about 2 minutes
    of CPU at the seed size); every denoising step after it reuses the compiled code.
    """

    def __init__(self, model: torch.nn.Module):
        self.model = model
        self.forward = compile_for_inference(model)

    def __call__(self, x_t: torch.Tensor, t: torch.Tensor, context: torch.Tensor | None) -> torch.Tensor:
        return self.forward(x_t, t, context)

    def null_condition(self, context: torch.Tensor) -> torch.Tensor:
        return self.model.null_condition(context)


def root_xz_mask() -> torch.Tensor:
    """(24, 10) mask of the window-relative channels: the root's horizontal position (x, z; y is up).

    Training windows are canonicalised to start at x = z = 0 (:mod:`.data`), so long-form windows are
    in-painted and stitched with these channels relative to each window's start.
    """
    mask = torch.zeros(NUM_JOINTS, NUM_CHANNELS)
    mask[0, ROOT.start] = 1.0
    mask[0, ROOT.start + 2] = 1.0
    return mask


@torch.inference_mode()
def sample_dance(
    model: EMM,
    diffusion: GaussianDiffusion,
    music: torch.Tensor,
    frames: torch.Tensor | None = None,
    head: torch.Tensor | None = None,
    sampler: str = "ddim",
    sampling_steps: int = 50,
    eta: float = 1.0,
    guidance_weight: float = 2.0,
    head_guidance_weight: float = 0.05,
    head_guidance_steps: int = 1,
    post_step=None,
    generator: torch.Generator | None = None,
    progress: bool = False,
    compile: bool = False,
    vision: torch.Tensor | None = None,
) -> torch.Tensor:
    """Motion tokens (B, T, 24, 10) for music (B, T, L), frames (B, T, 3, S, S) and head targets (B, T, 3).

    ``vision``: instead of ``frames``, their vision features z_v (B, T, Dc), what the model's vision
    encoder gives them (:func:`.video_features.encode_video` computes them from a decoded stream).

    ``sampler``, ``sampling_steps``, ``eta`` and ``guidance_weight`` are the options of
    :class:`~skeleton_mamba.tasks.training.diffusion.SamplingOptions`; ``head_guidance_weight`` and
    ``head_guidance_steps`` those of :class:`.guidance.HeadGuidance`. The condition (music + vision
    encoders + fusion) is encoded once, not per denoising step. ``compile``: run the denoiser as a
    :class:`CompiledDenoiser` (same samples to float32 rounding; worth it for many steps on a CPU).
    """
    b, t = music.shape[:2]
    context = model.encode_condition(music, frames, vision)
    guidance = []
    if head is not None and head_guidance_weight > 0:
        guidance.append(
            HeadGuidance(head, head_guidance_weight, head_guidance_steps, num_steps=diffusion.num_steps)
        )
    return sample(
        diffusion,
        CompiledDenoiser(model) if compile else model,
        (b, t, NUM_JOINTS, NUM_CHANNELS),
        context,
        sampler=sampler,
        sampling_steps=sampling_steps,
        eta=eta,
        guidance_weight=guidance_weight,
        guidance=guidance,
        post_step=post_step,
        generator=generator,
        device=music.device,
        dtype=music.dtype,
        progress=progress,
    )


def sample_long_dance(
    model: EMM,
    diffusion: GaussianDiffusion,
    music: torch.Tensor,
    frames: torch.Tensor | None = None,
    head: torch.Tensor | None = None,
    window: int = 150,
    overlap: int = 75,
    vision: torch.Tensor | None = None,
    **kwargs,
) -> torch.Tensor:
    """A whole track: music (T, L), frames (T, 3, S, S) or their vision features ``vision`` (T, Dc) (the
    vision encoder is per frame, so windows of features are the features of windows of frames; a long
    video need not be held), head (T, 3) -> tokens (T, 24, 10).

    The conditions are cut into windows every ``window - overlap`` frames (EDGE: 150 / 75; one padded
    window when the track is shorter), sampled as one batch by
    :func:`~skeleton_mamba.tasks.training.diffusion.sample_long` (overlaps in-painted after every step, the
    root's horizontal position relative to each window's start, as in training) and stitched into one
    continuous dance in the first window's frame. Head targets (T, 3) are moved into each window's frame
    by the head's own horizontal displacement since frame 0 (an approximation of the root's, which is only
    known once sampled). Other arguments as :func:`sample_dance`.
    """
    total = music.shape[0]
    music_w = split_windows(music, window, overlap)
    frames_w = None if frames is None else split_windows(frames, window, overlap)
    vision_w = None if vision is None else split_windows(vision, window, overlap)
    head_w = None
    if head is not None:
        head_w = split_windows(head, window, overlap)
        starts, _ = window_starts(total, window, overlap)
        shift = head[[min(s, total - 1) for s in starts]] - head[:1]
        shift[:, 1] = 0.0  # heights are absolute (floor at y = 0)
        head_w = head_w - shift[:, None]

    def windows(post_step) -> torch.Tensor:
        return sample_dance(
            model, diffusion, music_w, frames_w, head_w, post_step=post_step, vision=vision_w, **kwargs
        )

    return sample_long(windows, overlap, total, relative=root_xz_mask())


def tokens_to_motion(tokens: torch.Tensor, fps: float = 30.0) -> MotionData:
    """(T, 24, 10) tokens -> :class:`MotionData` with SMPL axis-angle poses, root and FK joints."""
    rotations, root, _ = decode_motion(tokens.detach().cpu().float())
    return MotionData(
        fps=fps,
        skeleton="smpl24",
        poses=matrix_to_axis_angle(rotations).numpy().astype(np.float32),
        trans=root.numpy().astype(np.float64),
        scaling=1.0,
        joints=motion_joints(tokens.detach().cpu().float()).numpy(),
    )
