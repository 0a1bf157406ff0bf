"""Right-padded batches: padded frames (or condition tokens) are removed by a select, never by a product."""

from __future__ import annotations

import torch


def zero_padding(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """``x`` (B, T, ...) with the frames where ``mask`` (B, T) is False set to 0.

    A select, not a product: ``NaN * 0`` is NaN, so a multiplication would let non-finite padding through.
    """
    keep = mask.reshape(*mask.shape, *([1] * (x.dim() - 2)))
    return torch.where(keep, x, torch.zeros((), dtype=x.dtype, device=x.device))
