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
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["resize_frames"]


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
