"""Long-form sampling by overlapping windows kept consistent during sampling (EDGE, Tseng et al. 2023).

A long sequence is cut into B windows of W frames starting every ``hop = W - overlap`` frames; the B
windows are sampled as one batch and, after every denoising step, the first ``overlap`` frames of window
b are overwritten by the last ``overlap`` frames of window b - 1 (:class:`WindowConsistency`), so the
windows agree on their overlaps when sampling ends and :func:`stitch_windows` joins them seamlessly.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

__all__ = ["window_starts", "split_windows", "WindowConsistency", "stitch_windows", "sample_long"]


def _check(window: int, overlap: int) -> None:
    if window < 1 or not 0 <= overlap <= window // 2:
        raise ValueError(
            f"need window >= 1 and 0 <= overlap <= window // 2, got window={window}, overlap={overlap}"
        )


def window_starts(total_frames: int, window: int, overlap: int) -> tuple[list[int], int]:
    """Start frames of the windows covering ``total_frames`` and the padded length they cover."""
    _check(window, overlap)
    hop = window - overlap
    count = 1 + max(0, math.ceil((total_frames - window) / hop))
    starts = [i * hop for i in range(count)]
    return starts, starts[-1] + window


def split_windows(sequence: torch.Tensor, window: int, overlap: int) -> torch.Tensor:
    """(T, ...) -> (B, window, ...) overlapping windows; the tail is padded by repeating the last frame."""
    starts, padded = window_starts(sequence.shape[0], window, overlap)
    if padded > sequence.shape[0]:
        pad = sequence[-1:].expand(padded - sequence.shape[0], *sequence.shape[1:])
        sequence = torch.cat([sequence, pad], dim=0)
    return torch.stack([sequence[s : s + window] for s in starts], dim=0)


class WindowConsistency:
    """Post-step projection ``x[b, :overlap] = x[b - 1, W - overlap:]`` for b >= 1; x (B, W, ...).

    Windows are processed in order, so every overlap chain starts from window 0.
    """

    def __init__(self, overlap: int):
        self.overlap = overlap

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        _check(x.shape[1], self.overlap)
        if self.overlap == 0 or x.shape[0] < 2:
            return x
        x = x.clone()
        w = x.shape[1]
        for b in range(1, x.shape[0]):
            x[b, : self.overlap] = x[b - 1, w - self.overlap :]
        return x


def stitch_windows(windows: torch.Tensor, overlap: int, total_frames: int | None = None) -> torch.Tensor:
    """(B, W, ...) -> (W + (B - 1)(W - overlap), ...) by a linear cross-fade over each overlap.

    With consistent windows (:class:`WindowConsistency`) the cross-fade is exact concatenation.
    ``total_frames`` crops the padded tail.
    """
    b, w = windows.shape[:2]
    _check(w, overlap)
    hop = w - overlap
    out = windows.new_zeros(w + (b - 1) * hop, *windows.shape[2:])
    weight = windows.new_zeros(out.shape[0])
    ramp = torch.ones(w, dtype=windows.dtype, device=windows.device)
    if overlap > 0:
        fade = torch.arange(1, overlap + 1, dtype=windows.dtype, device=windows.device) / (overlap + 1)
        ramp_in, ramp_out = ramp.clone(), ramp.clone()
        ramp_in[:overlap], ramp_out[w - overlap :] = fade, fade.flip(0)
    for i in range(b):
        r = ramp.clone()
        if overlap > 0:
            if i > 0:
                r = r * ramp_in
            if i < b - 1:
                r = r * ramp_out
        shape = (w,) + (1,) * (windows.ndim - 2)
        out[i * hop : i * hop + w] += windows[i] * r.reshape(shape)
        weight[i * hop : i * hop + w] += r
    out = out / weight.reshape((-1,) + (1,) * (windows.ndim - 2))
    return out if total_frames is None else out[:total_frames]


def sample_long(
    sample_fn: Callable[[Callable[[torch.Tensor], torch.Tensor]], torch.Tensor],
    overlap: int,
    total_frames: int | None = None,
) -> torch.Tensor:
    """Run ``sample_fn(post_step)`` (a sampler call producing (B, W, ...) windows) with window
    consistency as its post-step projection, then stitch the windows into one sequence."""
    windows = sample_fn(WindowConsistency(overlap))
    return stitch_windows(windows, overlap, total_frames)
