"""MMV, the Motion-Music-Vision score of EgoMusic ([EgoMusic] supp. Sec. 7.1).

``MMV = 1/2 MM(B_x, B_y) + 1/2 MV(B_x', B_z)`` with

* ``MM = 1/|B_y| sum_(t_y in B_y) exp(-min_(t_x in B_x) |t_x - t_y|^2 / (2 sigma^2))``: Bailando's
  music-beat-averaged BeatAlign (``B_x`` kinematic beats of the whole body, ``B_y`` music beats);
* ``MV = 1/|B_z| sum_(t_z in B_z) exp(-min_(t_x' in B_x') |t_x' - t_z|^2 / (2 sigma^2))`` with ``B_x'``
  the kinematic beats of the **head** joint and ``B_z`` the local minima of the optical-flow magnitude of
  the egocentric video.

Choices the supplement leaves open (documented here, all arguments): ``sigma`` is Bailando's 3 frames at
60 fps scaled to the motion fps; head beats use Bailando's envelope (per-frame speed of joint 15, Gaussian
smoothing 5 frames at 60 fps, local minima); the flow signal is the mean Farneback magnitude (OpenCV,
tutorial parameters) between frames ``t`` and ``t + 1`` stored at index ``t`` (the same convention as the
kinematic envelope), smoothed the same way; a video at another frame rate has its beat times converted to
motion frames. Videos are a ``(T, H, W, 3)`` uint8 array, a folder of images or a video file (imageio).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import imageio.v2 as imageio
import numpy as np
import torch
from scipy.ndimage import gaussian_filter
from scipy.signal import argrelextrema
from torchmetrics import Metric

from skeleton_mamba.tasks.motion.metrics.beat_align import (
    alignment_score,
    kinematic_beats,
    sequence_beat_align,
)
from skeleton_mamba.tasks.motion.metrics.common import Positions, as_sequences

__all__ = ["MMV", "flow_magnitudes", "load_video_frames", "visual_beats"]

Video = np.ndarray | torch.Tensor | str | os.PathLike
_IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp"}
_REFERENCE_FPS = 60.0
HEAD_JOINT = 15  # SMPL-24 "head"


def load_video_frames(video: Video) -> np.ndarray:
    """``(T, H, W, 3)`` uint8 frames from an array, a folder of images (sorted by name) or a video file.

    Examples:
        >>> import numpy as np
        >>> load_video_frames(np.zeros((4, 8, 8, 3), np.uint8)).shape
        (4, 8, 8, 3)
    """
    if isinstance(video, (np.ndarray, torch.Tensor)):
        frames = np.asarray(video.cpu() if isinstance(video, torch.Tensor) else video)
        if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
            raise ValueError(f"video array must be (T, H, W, 3) uint8, got {frames.shape} {frames.dtype}")
        return frames

    path = Path(video)
    if path.is_dir():
        files = sorted(f for f in path.iterdir() if f.suffix.lower() in _IMAGE_SUFFIXES)
        if not files:
            raise ValueError(f"{path}: no image files ({', '.join(sorted(_IMAGE_SUFFIXES))}) in the folder")
        images = [imageio.imread(f) for f in files]
    elif path.is_file():
        try:
            with imageio.get_reader(path) as reader:
                images = [np.asarray(frame) for frame in reader]
        except Exception as err:  # imageio raises plugin-specific types
            raise ValueError(f"{path}: cannot read video ({type(err).__name__}: {err})") from err
    else:
        raise FileNotFoundError(f"{path}: no such video file or image folder")
    images = [np.repeat(im[..., None], 3, -1) if im.ndim == 2 else im[..., :3] for im in images]
    if len({im.shape for im in images}) != 1:
        raise ValueError(f"{path}: frames have different sizes")
    return np.stack(images).astype(np.uint8)


def flow_magnitudes(video: Video) -> np.ndarray:
    """``(T - 1,)`` mean Farneback optical-flow magnitude between frames ``t`` and ``t + 1``.

    Examples:
        A bright square moving 2 pixels right per frame:

        >>> import numpy as np
        >>> frames = np.zeros((3, 64, 64, 3), np.uint8)
        >>> for t in range(3):
        ...     frames[t, 24:40, 20 + 2 * t : 36 + 2 * t] = 255
        >>> flow = flow_magnitudes(frames)
        >>> flow.shape, bool((flow > 0).all())
        ((2,), True)
    """
    import cv2  # lazy: OpenCV only for the MMV metric

    frames = load_video_frames(video)
    if len(frames) < 2:
        raise ValueError(f"optical flow needs at least 2 frames, got {len(frames)}")
    gray = [cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY) for f in frames]
    out = np.empty(len(gray) - 1)
    for t in range(len(gray) - 1):
        flow = cv2.calcOpticalFlowFarneback(gray[t], gray[t + 1], None, 0.5, 3, 15, 3, 5, 1.2, 0)
        out[t] = np.linalg.norm(flow, axis=-1).mean()
    return out


def visual_beats(video: Video, fps: float = 30.0, video_fps: float | None = None) -> np.ndarray:
    """Motion-frame indices of the local minima of the smoothed flow magnitude of ``video``.

    Args:
        video: frames (see :func:`load_video_frames`).
        fps: motion frame rate (beats are returned in motion frames).
        video_fps: video frame rate (default ``fps``).

    Examples:
        A square moving right and back (its flow stops at the turns, every 30 frames of 30 fps video):

        >>> import numpy as np
        >>> x = np.round(20 * np.sin(2 * np.pi * np.arange(120) / 60)).astype(int)
        >>> frames = np.zeros((120, 64, 64, 3), np.uint8)
        >>> for t in range(120):
        ...     frames[t, 24:40, 24 + x[t] : 40 + x[t]] = 255
        >>> visual_beats(frames, fps=30.0).tolist()
        [15, 45, 75, 105]
    """
    video_fps = fps if video_fps is None else video_fps
    signal = gaussian_filter(flow_magnitudes(video), 5 * video_fps / _REFERENCE_FPS)
    minima = argrelextrema(signal, np.less)[0]
    return np.round(minima * fps / video_fps).astype(np.int64)


class MMV(Metric):
    """Motion-Music-Vision score (EgoMusic), averaged over sequences; ``compute()`` returns a dict.

    Args:
        fps: motion frame rate (EgoMusic: 30).
        video_fps: egocentric video frame rate (default ``fps``).
        head_joint: index of the head joint (SMPL-24: 15).

    ``update(positions, music_beats, videos=None, video_beats=None)``: ``(B, T, J, 3)`` generated joints
    (or a list), one music-beat vector per sequence (one-hot or frame indices), and either the egocentric
    ``videos`` (arrays, image folders or files) or precomputed ``video_beats`` (frame indices, see
    :func:`visual_beats`). ``compute()`` gives ``{"mmv", "mm", "mv"}``.

    Examples:
        >>> import torch
        >>> t = torch.arange(120.0)
        >>> dance = torch.zeros(1, 120, 24, 3)
        >>> dance[0, :, :, 0] = torch.sin(2 * torch.pi * t / 60)[:, None]  # turns at frames 15, 45, 75, 105
        >>> mmv = MMV(fps=30.0)
        >>> mmv.update(dance, music_beats=[[15, 45, 75, 105]], video_beats=[[15, 45, 75, 105]])
        >>> {k: round(float(v), 3) for k, v in mmv.compute().items()}
        {'mmv': 0.801, 'mm': 0.801, 'mv': 0.801}
    """

    is_differentiable = False
    higher_is_better = True
    full_state_update = False

    def __init__(
        self, fps: float = 30.0, video_fps: float | None = None, head_joint: int = HEAD_JOINT, **kwargs: Any
    ) -> None:
        super().__init__(**kwargs)
        self.fps = fps
        self.video_fps = video_fps
        self.head_joint = head_joint
        for name in ("mm_sum", "mv_sum"):
            self.add_state(name, default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("count", default=torch.tensor(0, dtype=torch.long), dist_reduce_fx="sum")

    def update(
        self,
        positions: Positions,
        music_beats: Sequence[Any] | torch.Tensor | np.ndarray,
        videos: Sequence[Video] | None = None,
        video_beats: Sequence[Sequence[int] | np.ndarray] | None = None,
    ) -> None:
        sequences = as_sequences(positions, min_frames=3)
        if (videos is None) == (video_beats is None):
            raise ValueError("pass exactly one of videos or video_beats")
        visual = video_beats if video_beats is not None else videos
        if len(music_beats) != len(sequences) or len(visual) != len(sequences):
            raise ValueError(
                f"got {len(sequences)} motions, {len(music_beats)} music-beat vectors, {len(visual)} videos"
            )
        sigma = 3.0 * self.fps / _REFERENCE_FPS
        for seq, beats, vis in zip(sequences, music_beats, visual, strict=True):
            if not 0 <= self.head_joint < seq.shape[1]:
                raise ValueError(f"head_joint {self.head_joint} out of range for {seq.shape[1]} joints")
            b_z = (
                np.asarray(vis, dtype=np.int64)
                if video_beats is not None
                else visual_beats(vis, self.fps, self.video_fps)
            )
            b_z = b_z[b_z < seq.shape[0] - 1]
            head = kinematic_beats(seq[:, [self.head_joint]], "bailando", self.fps)
            self.mm_sum += sequence_beat_align(seq, beats, "bailando", self.fps)
            self.mv_sum += alignment_score(b_z, head, sigma)
            self.count += 1

    def compute(self) -> dict[str, torch.Tensor]:
        if self.count == 0:
            raise RuntimeError("MMV.compute() called before any update()")
        mm = self.mm_sum / self.count
        mv = self.mv_sum / self.count
        return {"mmv": 0.5 * mm + 0.5 * mv, "mm": mm, "mv": mv}
