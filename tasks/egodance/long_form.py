"""Long-form dance: how a track is cut into windows, and each window's head-guidance targets.

A track longer than the training window is sampled as overlapping windows
(:func:`.sampling.sample_long_dance`). Head guidance needs targets in the frame each window is sampled in:

- a model whose windows keep the world yaw: one trajectory for the whole track, in the first window's frame
  (:func:`.head_estimator.estimate_long_trajectory`, or a sample's ground truth), which the sampler moves into
  each window's frame by the head's horizontal displacement;
- a model trained on windows turned to face their first heading (``canonicalize_init_head``): each window's
  targets in its own frame, known before sampling without the sampled motion: estimated from that window's
  frames alone (:func:`.head_estimator.estimate_window_trajectories`, what the estimator was trained to do),
  or, for the oracle, the ground-truth head moved into the frame of the true pose at the window's first frame,
  as the data module canonicalises a training window (:class:`.heading_frames.HeadingFrames`).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.egodance.head_estimator import (
    HeadFrameFeatures,
    HeadTrajectoryEstimator,
    estimate_long_trajectory,
    estimate_window_trajectories,
)
from skeleton_mamba.tasks.egodance.heading_frames import HeadingFrames
from skeleton_mamba.tasks.training.diffusion.stitching import split_windows, window_starts

__all__ = ["LongForm", "head_targets"]


@dataclass(frozen=True)
class LongForm:
    """How a track is cut into windows (:func:`.sampling.sample_long_dance`).

    Attributes:
        window: frames per window (the training window). overlap: frames shared by consecutive windows.
        canonical: the model's windows face their first frame's head heading (``canonicalize_init_head``).
    """

    window: int = 150
    overlap: int = 75
    canonical: bool = False

    @property
    def hop(self) -> int:
        return self.window - self.overlap

    def starts(self, total: int) -> list[int]:
        """The windows' first frames for a ``total``-frame track."""
        return window_starts(total, self.window, self.overlap)[0]


def head_targets(
    source: str,
    long_form: LongForm,
    total: int,
    estimator: HeadTrajectoryEstimator | None = None,
    video: torch.Tensor | HeadFrameFeatures | None = None,
    truth: torch.Tensor | None = None,
    head: torch.Tensor | None = None,
) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """``(head, head_windows)`` for :func:`.sampling.sample_long_dance` (module docstring).

    Args:
        source: ``estimate``, ``oracle`` or ``none``.
        long_form: the windows; ``total``: the track's frames.
        estimator: the head-trajectory estimator (``estimate``).
        video: the frames (T, 3, H, W) or their :class:`HeadFrameFeatures` (``estimate``; features prepared
            with the windows' hop for a canonical model).
        truth: (T, 24, 10) ground-truth motion tokens, ``head`` (T, 3) ground-truth head positions, both in
            the track's frame (``oracle``).
    """
    if source == "none":
        return None, None
    if source == "oracle":
        if head is None or (long_form.canonical and truth is None):
            raise InputError("--head oracle needs the ground-truth camera path of a --sample")
        if not long_form.canonical:
            return head, None
        starts = long_form.starts(total)
        frames = HeadingFrames(turn=True)
        first = truth[[min(s, total - 1) for s in starts]]
        windows = split_windows(head, long_form.window, long_form.overlap)
        return None, frames.points_to_frame(windows, frames.relative_frame(first))
    if source != "estimate":
        raise ValueError(f"unknown head source {source!r} (estimate, oracle, none)")
    if estimator is None or video is None:
        raise InputError("the checkpoint has no head-trajectory estimator (music-only): use --head none")
    estimator = estimator.eval()
    if not long_form.canonical:
        return estimate_long_trajectory(estimator, video, long_form.window)[0], None
    starts = long_form.starts(total)
    return None, estimate_window_trajectories(estimator, video, starts, long_form.window)[0]
