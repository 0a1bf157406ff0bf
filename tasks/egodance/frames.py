"""Resizing egocentric frames for the vision encoder and the head-trajectory estimator.

One function, used wherever frames change size (the data set, ``sm dance``, :class:`.encoders.VisionEncoder`,
:class:`.head_estimator.HeadTrajectoryEstimator`), so training and inference see the same pixels.

- Bilinear, with antialiasing when shrinking (PyTorch's ``interpolate(antialias=True)``, the PIL-style
  triangle filter whose support grows with the scale factor). kornia's ``resize(antialias=True)`` blurs
  with a Gaussian by grouped 1-D convolutions first, which oneDNN runs an order of magnitude slower on the
  CPU.
- The result is in the standard, contiguous (N, 3, H, W) layout. Decoded video permuted from (H, W, 3)
  is channels-last in memory, and on torch 2.13's CPU build oneDNN's convolution backward on such input
  corrupted the heap ("double free or corruption" while training the vision encoder).

Reading: :func:`iter_video_frames` decodes a video file (ffmpeg, one frame at a time) or a folder of images
and resizes chunks of :data:`DECODE_CHUNK` frames as they are read, so memory holds one chunk at the source
resolution, whatever the video's size; :func:`read_video_frames` keeps every frame at the model's resolution
(short clips, tests), while ``sm dance --video`` keeps only per-frame features (:mod:`.video_features`), in
memory that does not grow with the video's length. Images and video frames larger than
:data:`MAX_IMAGE_PIXELS` are refused from their header, before anything is decoded.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

from skeleton_mamba.errors import InputError

__all__ = [
    "DECODE_CHUNK",
    "IMAGE_SUFFIXES",
    "MAX_IMAGE_PIXELS",
    "VideoHeader",
    "iter_video_frames",
    "read_image",
    "read_video_frames",
    "resize_frames",
    "video_header",
]

MAX_IMAGE_PIXELS = 40_000_000  # an image or video frame: 8K UHD (7680x4320 = 33.2 MP) fits
DECODE_CHUNK = 16  # frames decoded at the source resolution before they are resized
CHUNK_PIXELS = 16 * 1280 * 720  # at most this many source pixels per chunk (16 HD frames; one 8K frame):
# a chunk is held as uint8 and as float before it is resized, 13 bytes a pixel (about 190 MB here)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")


def resize_frames(images: torch.Tensor, size: int | tuple[int, int]) -> torch.Tensor:
    """(N, 3, H, W) float images -> (N, 3, S_h, S_w), contiguous (returned as they are, made contiguous,
    when already of that size)."""
    if images.ndim != 4:
        raise ValueError(f"expected images (N, C, H, W), got {tuple(images.shape)}")
    size = (size, size) if isinstance(size, int) else tuple(size)
    images = images.contiguous()
    if tuple(images.shape[-2:]) == size:
        return images
    return F.interpolate(images, size=size, mode="bilinear", align_corners=False, antialias=True)


def _refuse_size(path: Path, width: int, height: int, what: str = "image") -> None:
    if width * height > MAX_IMAGE_PIXELS:
        raise InputError(f"{path}: the {what} is {width}x{height} ({width * height / 1e6:.1f} megapixels), "
                         f"more than the {MAX_IMAGE_PIXELS / 1e6:g} megapixels admitted")  # fmt: skip


def read_image(path: str | Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB pixels of an image file; its size is checked from the header before decoding.

    Raises:
        InputError: more than :data:`MAX_IMAGE_PIXELS` pixels, or not a readable image (names the file).
    """
    path = Path(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # our own bound is lower
            with Image.open(path) as image:  # reads the header only
                _refuse_size(path, *image.size)
                return np.asarray(image.convert("RGB"))
    except Image.DecompressionBombError as e:
        pixels = re.search(r"\((\d+) pixels\)", str(e))
        claimed = f" ({int(pixels.group(1)) / 1e6:.1f} megapixels)" if pixels else ""
        raise InputError(f"{path}: the image is larger{claimed} than the {MAX_IMAGE_PIXELS / 1e6:g} "
                         "megapixels admitted") from None  # fmt: skip
    except (OSError, SyntaxError, ValueError) as e:  # PIL: unidentified, truncated or damaged images
        if isinstance(e, InputError):
            raise
        raise InputError(f"{path}: not a readable image ({type(e).__name__}: {e})") from None


def _to_chunk(images: list[np.ndarray], size: int | tuple[int, int]) -> torch.Tensor:
    rgb = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2).contiguous()  # uint8: the cheap copy
    return resize_frames(rgb.float().div_(255.0), size)  # one float copy of the chunk, scaled in place


@dataclass(frozen=True)
class VideoHeader:
    """What a video's header (or an image folder's listing) says before any frame is decoded.

    Attributes:
        frames: the frame count (from the header's duration and rate; None when the header gives none).
        fps: the frame rate (None for an image folder, whose frames are taken at the model's rate).
        width, height: the frame size in pixels (None when the header gives none, and for an image folder).
    """

    frames: int | None
    fps: float | None
    width: int | None = None
    height: int | None = None

    def frames_at(self, fps: float) -> int | None:
        """The frame count once the video is taken at ``fps`` (:func:`iter_video_frames`)."""
        if self.frames is None:
            return None
        return self.frames if self.fps is None else _resampled_count(self.frames, self.fps, fps)


def video_header(path: str | Path) -> VideoHeader:
    """The frame count and rate of a video file (its header only) or an image folder (its listing).

    Raises:
        FileNotFoundError: no such file or folder.
        InputError: not a readable video (names the file).
    """
    path = Path(path)
    if path.is_dir():
        return VideoHeader(sum(p.suffix.lower() in IMAGE_SUFFIXES for p in path.iterdir()), None)
    if not path.is_file():
        raise FileNotFoundError(2, "No such video file or image folder", str(path))
    reader, meta = _open_video(path)
    reader.close()
    fps, duration = float(meta.get("fps") or 0.0), float(meta.get("duration") or 0.0)
    size = meta.get("size") or (None, None)
    width, height = (int(v) if v else None for v in size)
    if not (np.isfinite(fps) and fps > 0):
        return VideoHeader(None, None, width, height)
    return VideoHeader(int(round(duration * fps)) if duration > 0 else None, fps, width, height)


def _resampled_count(frames: int, source_fps: float, fps: float) -> int:
    """Frames k = 0, 1, ... at ``fps`` whose nearest source frame exists."""
    if not _differs(source_fps, fps):
        return frames
    return int(np.floor((frames - 0.5) * fps / source_fps)) + 1


def _differs(source_fps: float, fps: float) -> bool:
    """Rates more than 0.1 % apart (29.97 is not 30: over a 3-minute song they drift by 5 frames)."""
    return abs(source_fps - fps) > 1e-3 * fps


def _open_video(path: Path) -> tuple[Iterator[bytes], dict]:
    """An ffmpeg reader of the video's RGB frames and its header (the reader's first item)."""
    reader = imageio_ffmpeg.read_frames(str(path), pix_fmt="rgb24")
    try:
        return reader, next(reader)
    except (OSError, RuntimeError, StopIteration) as e:
        reader.close()
        reason = str(e).strip().splitlines()[-1] if str(e).strip() else type(e).__name__
        raise InputError(f"{path}: not a readable video ({reason[:200]})") from None


def _at_rate(frames: Iterator[np.ndarray], source_fps: float, fps: float) -> Iterator[np.ndarray]:
    """The frames of a ``source_fps`` video taken at ``fps``: output frame k is the source frame nearest
    to its time, ``round(k * source_fps / fps)`` (frames dropped or repeated)."""
    k = 0
    for i, frame in enumerate(frames):
        while round(k * source_fps / fps) == i:
            yield frame
            k += 1


def _video_file_frames(path: Path) -> Iterator[np.ndarray]:
    """(H, W, 3) uint8 frames of a video file, decoded one at a time by ffmpeg."""
    reader, meta = _open_video(path)
    try:
        width, height = (int(v) for v in meta["size"])
        _refuse_size(path, width, height, "video frame")
        shape = (height, width, 3)
        try:
            for i, raw in enumerate(reader):
                if len(raw) != width * height * 3:
                    raise InputError(f"{path}: frame {i} has {len(raw)} bytes, expected {width}x{height} RGB")
                yield np.frombuffer(raw, np.uint8).reshape(shape)
        except (OSError, RuntimeError) as e:
            raise InputError(f"{path}: the video could not be decoded ({str(e).strip()[:200]})") from None
    finally:
        reader.close()  # stops ffmpeg when the caller stops early


def iter_video_frames(
    path: str | Path,
    size: int | tuple[int, int],
    max_frames: int | None = None,
    chunk: int = DECODE_CHUNK,
    fps: float | None = None,
) -> Iterator[torch.Tensor]:
    """Chunks (n <= ``chunk``, 3, S_h, S_w) float in [0, 1] of a video file or a folder of images
    (sorted by name), resized with :func:`resize_frames` as they are read; at most ``max_frames`` frames.
    A chunk holds at most :data:`CHUNK_PIXELS` source pixels (fewer frames of a large video), so memory
    does not grow with the frame size beyond one frame.
    ``fps``: take a video file at this rate (frames dropped or repeated, :func:`_at_rate`, when its header
    says another; an image folder's frames are taken as they are).

    Raises:
        FileNotFoundError: no such file or folder.
        InputError: an empty folder, an unreadable or too large image / video (names the file).
    """
    path = Path(path)
    if path.is_dir():
        names = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not names:
            raise InputError(f"{path}: holds no {'/'.join(IMAGE_SUFFIXES)} images")
        frames: Iterator[np.ndarray] = (read_image(p) for p in names)
    elif path.is_file():
        frames = _video_file_frames(path)
        source_fps = video_header(path).fps if fps is not None else None
        if source_fps is not None and _differs(source_fps, fps):
            frames = _at_rate(frames, source_fps, fps)
    else:
        raise FileNotFoundError(2, "No such video file or image folder", str(path))
    pending: list[np.ndarray] = []
    shape = None
    for count, frame in enumerate(frames):
        if max_frames is not None and count >= max_frames:
            break
        if shape is None:
            shape = frame.shape
            chunk = max(1, min(chunk, CHUNK_PIXELS // (shape[0] * shape[1])))
        elif frame.shape != shape:
            raise InputError(f"{path}: frame {count} is {frame.shape[1]}x{frame.shape[0]}, the first "
                             f"{shape[1]}x{shape[0]}")  # fmt: skip
        pending.append(frame)
        if len(pending) == chunk:
            yield _to_chunk(pending, size)
            pending = []
    if hasattr(frames, "close"):
        frames.close()
    if pending:
        yield _to_chunk(pending, size)


def read_video_frames(
    path: str | Path, size: int | tuple[int, int], max_frames: int | None = None
) -> torch.Tensor:
    """(T, 3, S_h, S_w) float frames of a video file or image folder at the model's resolution, decoded
    as a stream (:func:`iter_video_frames`); memory beyond the result is one chunk of source frames. The
    result grows with the video (600 KB a frame at 224 px): whole tracks go through
    :func:`.video_features.encode_video` instead."""
    chunks = list(iter_video_frames(path, size, max_frames))
    if not chunks:
        raise InputError(f"{Path(path)}: holds no frames")
    return torch.cat(chunks)
