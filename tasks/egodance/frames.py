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
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

from skeleton_mamba.tasks.motion.errors import InputError

__all__ = [
    "DECODE_CHUNK",
    "IMAGE_SUFFIXES",
    "MAX_IMAGE_PIXELS",
    "iter_video_frames",
    "read_image",
    "read_video_frames",
    "resize_frames",
]

MAX_IMAGE_PIXELS = 40_000_000  # an image or video frame: 8K UHD (7680x4320 = 33.2 MP) fits
DECODE_CHUNK = 16  # frames decoded at the source resolution before they are resized
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
    rgb = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2)
    return resize_frames(rgb.float() / 255.0, size)


def _video_file_frames(path: Path) -> Iterator[np.ndarray]:
    """(H, W, 3) uint8 frames of a video file, decoded one at a time by ffmpeg."""
    try:
        reader = imageio_ffmpeg.read_frames(str(path), pix_fmt="rgb24")
        meta = next(reader)
    except (OSError, RuntimeError, StopIteration) as e:
        reason = str(e).strip().splitlines()[-1] if str(e).strip() else type(e).__name__
        raise InputError(f"{path}: not a readable video ({reason[:200]})") from None
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
    path: str | Path, size: int | tuple[int, int], max_frames: int | None = None, chunk: int = DECODE_CHUNK
) -> Iterator[torch.Tensor]:
    """Chunks (n <= ``chunk``, 3, S_h, S_w) float in [0, 1] of a video file or a folder of images
    (sorted by name), resized with :func:`resize_frames` as they are read; at most ``max_frames`` frames.

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
    else:
        raise FileNotFoundError(2, "No such video file or image folder", str(path))
    pending: list[np.ndarray] = []
    shape = None
    for count, frame in enumerate(frames):
        if max_frames is not None and count >= max_frames:
            break
        if shape is None:
            shape = frame.shape
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
