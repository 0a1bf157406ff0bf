"""A whole egocentric video -> its per-frame features, decoded as a stream in memory bounded by the window.

Both users of the frames in ``sm dance`` reduce each frame to a small feature before anything looks
across frames:

- the EMM's :class:`.encoders.VisionEncoder` is per frame (ResNet pooled feature -> MLP, in eval mode),
  so the features z_v (T, Dc) of a track are those of its windows' frames
  (:func:`.sampling.sample_long_dance` cuts ``vision`` into the same windows as it would cut frames);
- the :class:`.head_estimator.HeadTrajectoryEstimator`'s CNN sees each frame with its difference to the
  previous one (zero at a window's first frame), and only its GRU looks across a window:
  :class:`.head_estimator.HeadFeatureStream` keeps the CNN features, the zero-difference features of the
  window starts and the last window's small frames.

:func:`encode_video` decodes the video chunk by chunk (:func:`.frames.iter_video_frames`, at the model's
resolution) and feeds both, so memory holds one chunk of frames, whatever the video's length or size, plus
Dc + dim floats per frame (1.5 KB at the paper's Dc = 256), not the 600 KB of a 224 px float frame.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.egodance.encoders import VisionEncoder
from skeleton_mamba.tasks.egodance.frames import DECODE_CHUNK, iter_video_frames
from skeleton_mamba.tasks.egodance.head_estimator import (
    HeadFeatureStream,
    HeadFrameFeatures,
    HeadTrajectoryEstimator,
)
from skeleton_mamba.tasks.egodance.video_rotation import HeadRotationStream, head_headings

__all__ = ["VideoFeatures", "encode_video"]


@dataclass
class VideoFeatures:
    """The per-frame features of a video's first ``num_frames`` frames.

    Attributes:
        num_frames: T.
        vision: z_v (T, Dc) of the vision encoder, or None (none given).
        head: the head-trajectory estimator's features, or None (none given).
        heading: (T,) the head's heading change since frame 0 (radians) read from the frames
            (:mod:`.video_rotation`), or None (no rotation tracker given).
    """

    num_frames: int
    vision: torch.Tensor | None = None
    head: HeadFrameFeatures | None = None
    heading: torch.Tensor | None = None


@torch.no_grad()
def encode_video(
    path: str | Path,
    image_size: int,
    vision_encoder: VisionEncoder | None = None,
    head_estimator: HeadTrajectoryEstimator | None = None,
    window: int = 150,
    max_frames: int | None = None,
    chunk: int = DECODE_CHUNK,
    progress: bool = False,
    hops: tuple[int, ...] = (),
    fps: float | None = None,
    rotation: HeadRotationStream | None = None,
) -> VideoFeatures:
    """Decode a video file or image folder as a stream at ``image_size`` and encode its frames.

    Args:
        path: the video (:func:`.frames.iter_video_frames`).
        image_size: the model's square frame size (frames are resized to it as they are decoded).
        vision_encoder: the EMM's vision encoder (eval mode), or None.
        head_estimator: the head-trajectory estimator (eval mode), or None.
        window: the head estimator's window (:func:`.head_estimator.estimate_long_trajectory`).
        hops: hops of other windows the head estimator will be run on
            (:func:`.head_estimator.estimate_window_trajectories`: long-form sampling's windows).
        fps: the model's frame rate: a video file of another rate is taken at this one
            (:func:`.frames.iter_video_frames`).
        rotation: a rotation tracker the frames are pushed to (:class:`.video_rotation.HeadRotationStream`),
            or None.
        max_frames: decode at most this many frames.
        chunk: frames decoded and encoded together.
        progress: show a progress bar (frames encoded).

    Raises:
        InputError: the video holds no frames, or cannot be read (names the file).
    """
    for part in (vision_encoder, head_estimator):
        if part is not None and part.training:
            raise ValueError(f"{type(part).__name__} must be in eval mode (per-frame features)")
    vision: list[torch.Tensor] = []
    head = None if head_estimator is None else HeadFeatureStream(head_estimator, window, hops)
    count = 0
    with tqdm(total=max_frames, desc="video", unit="frame", disable=not progress) as bar:
        for frames in iter_video_frames(path, image_size, max_frames, chunk, fps):
            if vision_encoder is not None:
                vision.append(vision_encoder(frames[None])[0])
            if head is not None:
                head.push(frames)
            if rotation is not None:
                rotation.push(frames)
            count += len(frames)
            bar.update(len(frames))
    if count == 0:
        raise InputError(f"{Path(path)}: holds no frames")
    return VideoFeatures(
        num_frames=count,
        vision=torch.cat(vision) if vision else None,
        head=None if head is None else head.finish(),
        heading=_headings(rotation, path),
    )


def _headings(rotation: HeadRotationStream | None, path: str | Path) -> torch.Tensor | None:
    """The head's headings read by ``rotation``, or None (no tracker; frames a rotation does not explain,
    said on one line)."""
    if rotation is None:
        return None
    camera = rotation.finish()
    if not rotation.reliable:
        warnings.warn(
            f"{Path(path)}: the frames do not show one scene turning (a rotation explains "
            f"{rotation.explained} of {len(rotation.steps)} frame pairs): the head's turns are not read from "
            "this video, each window's heading is the sampled motion's",
            stacklevel=3,
        )
        return None
    return head_headings(camera).float()
