"""Dance generation with a trained EMM: one window, or long-form by stitched windows, and decoding.

Sampling goes through the shared entry point :func:`~skeleton_mamba.tasks.training.diffusion.sample`
(DDIM, EDGE: 50 steps, eta 1; or ancestral DDPM, the original code, 1000 steps) with classifier-free guidance
(``guidance_weight``) and the head guidance G_head when head targets are given (:mod:`.guidance`);
long tracks through :func:`~skeleton_mamba.tasks.training.diffusion.sample_long`. With ``compile=True`` the
denoiser runs compiled with its weights frozen
(:func:`skeleton_mamba.runtime.compiling.compile_for_inference`).
"""

from __future__ import annotations

import numpy as np
import torch

from skeleton_mamba.runtime.compiling import compile_for_inference
from skeleton_mamba.tasks.egodance.dance_args import DEFAULT_BATCH_WINDOWS  # torch-free, for sm dance --help
from skeleton_mamba.tasks.egodance.guidance import HeadGuidance, HeadingGuidance
from skeleton_mamba.tasks.egodance.heading_frames import HeadingFrames
from skeleton_mamba.tasks.egodance.model import EMM
from skeleton_mamba.tasks.egodance.representation import (
    FPS,
    NUM_CHANNELS,
    NUM_JOINTS,
    decode_motion,
    motion_joints,
)
from skeleton_mamba.tasks.motion.body.rotations import matrix_to_axis_angle
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, sample, sample_long
from skeleton_mamba.tasks.training.diffusion.stitching import split_windows, window_starts

__all__ = [
    "DEFAULT_BATCH_WINDOWS",
    "CompiledDenoiser",
    "sample_dance",
    "sample_long_dance",
    "tokens_to_motion",
]


class CompiledDenoiser:
    """A denoiser's call ``(x_t, t, context) -> x0`` (an EMM's) compiled for inference, weights frozen.

    A :class:`~skeleton_mamba.tasks.training.diffusion.samplers.NullConditioned` denoiser like the model, so
    classifier-free guidance stays one call on the doubled batch. The first call compiles (its cost:
    ``benchmarks/README.md``, "Compiled EMM sampling"); every denoising step after it reuses the compiled
    code.
    """

    def __init__(self, model: torch.nn.Module):
        self.model = model
        self.forward = compile_for_inference(model)

    def __call__(self, x_t: torch.Tensor, t: torch.Tensor, context: torch.Tensor | None) -> torch.Tensor:
        return self.forward(x_t, t, context)

    def null_condition(self, context: torch.Tensor) -> torch.Tensor:
        return self.model.null_condition(context)


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
    heading: torch.Tensor | None = None,
    heading_weight: float = 1.0,
) -> torch.Tensor:
    """Motion tokens (B, T, 24, 10) for music (B, T, L), frames (B, T, 3, S, S) and head targets (B, T, 3).

    ``heading``: (B, T) the head's heading in each window's frame, read from the video
    (:mod:`.video_rotation`) or the camera path, held by :class:`.guidance.HeadingGuidance` with
    ``heading_weight`` (0: not held), and the condition of a model with ``heading_condition`` (required
    there).

    ``vision``: instead of ``frames``, their vision features z_v (B, T, Dc), what the model's vision
    encoder gives them (:func:`.video_features.encode_video` computes them from a decoded stream).

    ``sampler``, ``sampling_steps``, ``eta`` and ``guidance_weight`` are the options of
    :class:`~skeleton_mamba.tasks.training.diffusion.SamplingOptions`; ``head_guidance_weight`` and
    ``head_guidance_steps`` those of :class:`.guidance.HeadGuidance`. The condition (music + vision
    encoders + fusion) is encoded once, not per denoising step. ``compile``: run the denoiser as a
    :class:`CompiledDenoiser` (same samples to float32 rounding; worth it for many steps on a CPU).
    """
    b, t = music.shape[:2]
    conditioned = model.heading_embedding is not None
    context = model.encode_condition(music, frames, vision, heading if conditioned else None)
    guidance = []
    if head is not None and head_guidance_weight > 0:
        guidance.append(
            HeadGuidance(head, head_guidance_weight, head_guidance_steps, num_steps=diffusion.num_steps)
        )
    if heading is not None and heading_weight > 0:
        guidance.append(HeadingGuidance(heading, heading_weight))
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
    *,
    canonical: bool = False,
    head_windows: torch.Tensor | None = None,
    batch_windows: int | None = DEFAULT_BATCH_WINDOWS,
    inpaint_last: bool = False,
    headings: torch.Tensor | None = None,
    join: bool = True,
    inpaint: bool = True,
    **kwargs,
) -> torch.Tensor:
    """A whole track: music (T, L), frames (T, 3, S, S) or their vision features ``vision`` (T, Dc) (the
    vision encoder is per frame, so frames are encoded once each, and a long video need not be held)
    -> tokens (T, 24, 10), one continuous dance in the first window's frame.

    The conditions are cut into windows every ``window - overlap`` frames (EDGE: 150 / 75; one padded
    window when the track is shorter) and sampled by
    :func:`~skeleton_mamba.tasks.training.diffusion.sample_long`, ``batch_windows`` windows at a time
    (memory bounded whatever the track's length): every overlap is in-painted after every denoising step in
    the frame of the window it belongs to, as the model was trained (:class:`.heading_frames.HeadingFrames`):
    the root's horizontal position relative to the window's first frame and, for a model trained with
    ``canonicalize_init_head`` (``canonical``), the window turned to face its first frame's head heading,
    both taken from the previous window's sampled motion. The windows are then turned back and joined, their
    overlaps cross-faded (``inpaint_last``: in-painted after the last step too, as before the cross-fade).

    Head guidance: ``head`` (T, 3) targets in the track's frame, moved into each window's frame by the
    head's own horizontal displacement since frame 0 (an approximation of the root's, which is only known
    once sampled; world-yaw models only), or ``head_windows`` (B, window, 3): each window's targets in its
    own frame (:func:`.head_estimator.estimate_window_trajectories`; what a ``canonical`` model needs, since
    its windows' headings are only known once sampled). Other arguments as :func:`sample_dance`.

    Heading anchor: ``headings`` (T,) the head's heading through the track (radians, relative to frame 0),
    read from the egocentric video (:class:`.video_rotation.HeadRotationStream`; a ``canonical`` model).
    Each window's frame is then turned from the one before by the heading the video turned between their
    first frames (the ``anchors`` of :func:`~skeleton_mamba.tasks.training.diffusion.sample_long`), not by
    the sampled motion's, and each window's head is held to the video's heading in that frame
    (:class:`.guidance.HeadingGuidance`), so the dance faces where the dancer faced however long the track.
    A model with ``heading_condition`` needs ``headings``: each window's turns since its first frame are its
    condition (a world-yaw model's only use of them).

    ``inpaint=False``: the overlaps are not in-painted (each window is sampled from its own conditions, its
    frame still found from the window before), the windows joined by the cross-fade alone.

    ``join=False``: the same windows with the same noise sampled each alone, (B, window, 24, 10) in their own
    frames (:func:`~skeleton_mamba.tasks.training.diffusion.sample_long`).
    """
    if frames is not None and vision is not None:
        raise ValueError("give frames or their vision features, not both")
    if head is not None and head_windows is not None:
        raise ValueError("give head targets for the track (head) or per window (head_windows), not both")
    if canonical and head is not None:
        raise ValueError(
            "a model trained on windows turned to face their first heading needs its head targets per "
            "window (head_windows), in each window's own frame"
        )
    if headings is not None and not canonical:
        if model.heading_embedding is None:
            raise ValueError(
                "heading anchors need a model whose windows face their first heading (canonical)"
            )
        kwargs["heading_weight"] = 0.0  # world-yaw windows: the turns condition the model, nothing is held
    total = music.shape[0]
    starts, _ = window_starts(total, window, overlap)
    if head_windows is not None and head_windows.shape[:2] != (len(starts), window):
        raise ValueError(f"head_windows {tuple(head_windows.shape)}: expected ({len(starts)}, {window}, 3)")
    if frames is not None and model.vision_encoder is not None:  # each frame once, not once per window
        vision, frames = model.vision_encoder(frames[None])[0], None
    music_w = split_windows(music, window, overlap)
    vision_w = None if vision is None else split_windows(vision, window, overlap)
    anchors = heading_w = None
    if headings is not None:
        if headings.shape != (total,):
            raise ValueError(f"headings {tuple(headings.shape)}: expected ({total},), one per frame")
        first = headings[[min(s, total - 1) for s in starts]].to(music.dtype)
        heading_w = split_windows(headings.to(music.dtype), window, overlap) - first[:, None]
        if canonical:
            anchors = torch.full((len(starts), 3), float("nan"), dtype=music.dtype)
            anchors[1:, 0] = first[1:] - first[:-1]
    head_w = head_windows
    if head is not None:
        head_w = split_windows(head, window, overlap)
        shift = head[[min(s, total - 1) for s in starts]] - head[:1]
        shift[:, 1] = 0.0  # heights are absolute (floor at y = 0)
        head_w = head_w - shift[:, None]

    def windows(post_step, which: slice) -> torch.Tensor:
        return sample_dance(
            model,
            diffusion,
            music_w[which],
            None,
            None if head_w is None else head_w[which],
            post_step=post_step,
            vision=None if vision_w is None else vision_w[which],
            heading=None if heading_w is None else heading_w[which],
            **kwargs,
        )

    return sample_long(
        windows,
        overlap,
        total,
        frames=HeadingFrames(turn=canonical),
        num_windows=len(starts),
        batch_windows=batch_windows,
        inpaint_last=inpaint_last,
        anchors=anchors,
        join=join,
        inpaint=inpaint,
    )


def tokens_to_motion(tokens: torch.Tensor, fps: float = FPS) -> MotionData:
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
