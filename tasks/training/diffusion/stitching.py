"""Long-form sampling by overlapping windows kept consistent during sampling ([EDGE]; EDGE
``model/diffusion.py`` ``long_ddim_sample``).

A long sequence is cut into B windows of W frames starting every ``hop = W - overlap`` frames; the B
windows are sampled as one batch and, after every denoising step, the first ``overlap`` frames of window
b are overwritten by the last ``overlap`` frames of window b - 1 (:class:`WindowConsistency`), so the
windows agree on their overlaps when sampling ends and :func:`stitch_windows` joins them seamlessly.
Channels that the task expresses relative to each window's start (a root trajectory canonicalised to
start at the origin) are in-painted shifted by where the window starts, so the model sees in-distribution
inputs and the stitched trajectory continues across seams (:meth:`WindowConsistency.to_global`).
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
    """Post-step in-painting of the overlaps (:data:`.samplers.PostStep`); x (B, W, ...).

    For b >= 1, in order (so every overlap chain starts from window 0)::

        x[b, :overlap] = x[b - 1, W - overlap:] - signal * offset_b,
        offset_b = relative * x0_hat[b - 1, W - overlap]

    ``relative`` (broadcastable to one frame, x.shape[2:]; None: no such channel) marks the channels that
    hold positions relative to each window's own first frame, as in data canonicalised per window (e.g.
    the root's horizontal position, 0 at frame 0). ``offset_b`` is where window b starts in window b - 1's
    frame, taken from the clean prediction x0_hat; it is scaled by ``signal`` = sqrt(alpha_bar) because
    x = signal * x0 + noise (shifting x0 by d shifts x by signal * d). After the last step (signal 1,
    x = x0_hat) window b starts exactly at 0 in its own frame and continues window b - 1 exactly;
    :meth:`to_global` adds the accumulated offsets to bring every window into window 0's frame.

    Args:
        overlap: frames shared by consecutive windows.
        relative: the per-window-relative channel mask, or None.
    """

    def __init__(self, overlap: int, relative: torch.Tensor | None = None):
        self.overlap = overlap
        self.relative = relative
        self.offsets: torch.Tensor | None = None  # (B, ...) offset_b of the last call (offset_0 = 0)

    def __call__(
        self, x: torch.Tensor, x0: torch.Tensor | None = None, signal: torch.Tensor | float = 1.0
    ) -> torch.Tensor:
        _check(x.shape[1], self.overlap)
        offsets = x.new_zeros(x.shape[0], *x.shape[2:])
        if self.overlap == 0 or x.shape[0] < 2:
            self.offsets = offsets
            return x
        w = x.shape[1]
        hop = w - self.overlap
        if self.relative is not None and x0 is not None:
            rel = self.relative.to(x.device, x.dtype)
            offsets[1:] = x0[:-1, hop] * rel
        scale = torch.as_tensor(signal, dtype=x.dtype, device=x.device).reshape(-1)
        scale = scale.expand(x.shape[0]).reshape(-1, *([1] * (x.ndim - 2)))
        x = x.clone()
        for b in range(1, x.shape[0]):
            x[b, : self.overlap] = x[b - 1, hop:] - scale[b] * offsets[b]
        self.offsets = offsets
        return x

    def to_global(self, windows: torch.Tensor) -> torch.Tensor:
        """(B, W, ...) windows in their own frames -> in window 0's frame (cumulative offsets added)."""
        if self.offsets is None:
            return windows
        return windows + self.offsets.cumsum(0)[:, None].to(windows.dtype)


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
    sample_fn: Callable[[WindowConsistency], torch.Tensor],
    overlap: int,
    total_frames: int | None = None,
    relative: torch.Tensor | None = None,
) -> torch.Tensor:
    """Run ``sample_fn(post_step)`` (a sampler call producing (B, W, ...) windows) with window
    consistency (``relative`` channels as :class:`WindowConsistency`) as its post-step projection,
    then stitch the windows, in window 0's frame, into one sequence."""
    consistency = WindowConsistency(overlap, relative)
    windows = sample_fn(consistency)
    return stitch_windows(consistency.to_global(windows), overlap, total_frames)
