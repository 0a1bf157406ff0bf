"""Long-form sampling by overlapping windows kept consistent during sampling ([EDGE]; EDGE
``model/diffusion.py`` ``long_ddim_sample``).

A long sequence is cut into B windows of W frames starting every ``hop = W - overlap`` frames; the B
windows are sampled as one batch and, after every denoising step, the first ``overlap`` frames of window
b are overwritten by the last ``overlap`` frames of window b - 1 (:class:`WindowConsistency`), so the
windows agree on their overlaps when sampling ends and :func:`stitch_windows` joins them seamlessly.
Tasks whose windows are canonicalised at their first frame (a root trajectory that starts at the origin;
a window turned to face its first heading) give their :mod:`.window_frames`: each overlap is in-painted in
the frame of the window it belongs to, so the model sees in-distribution inputs, and the stitched
sequence continues across seams in the first window's frame (:meth:`WindowConsistency.to_global`). Long
sequences are sampled in bounded batches of windows, each batch continuing the last (:func:`sample_long`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

from skeleton_mamba.tasks.training.diffusion.window_frames import TranslationFrames, WindowFrames

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

        x[b, :overlap] = to_frame(x[b - 1, W - overlap:], frame_b, signal),
        frame_b = relative_frame(x0_hat[b - 1, W - overlap])

    ``frames`` (:class:`.window_frames.WindowFrames`; None: every window in one frame) says how window b's
    own frame relates to window b - 1's: it is found from where window b starts in window b - 1, taken
    from the clean prediction x0_hat, and ``to_frame`` moves the noisy overlap into it with its
    translations scaled by ``signal`` = sqrt(alpha_bar) (x = signal * x0 + noise). After the last step
    (signal 1, x = x0_hat) window b starts in its own frame exactly where window b - 1 puts it and continues
    it exactly; :meth:`to_global` brings every window into the frame of the first (or of ``base``).

    ``relative`` is the shorthand for translation-only frames (:class:`.window_frames.TranslationFrames`):
    the channels that hold positions relative to each window's own first frame, as in data canonicalised
    per window (e.g. the root's horizontal position, 0 at frame 0).

    ``inpaint_last``: also in-paint after the last step (signal 1). By default the last step's predictions are
    kept as they are, as [EDGE] does (it in-paints only while t > 0): the overlaps then agree up to what the
    last step changed, and :func:`stitch_windows` cross-fades them. Overwriting them instead joins window b's
    copy of window b - 1's tail to window b's own continuation of its own prediction, which differ by that
    last change: a step in position and velocity at the end of every overlap (a click every hop).

    ``prefix``: a motion already sampled that window 0 must continue (the last ``overlap`` frames of the
    window before it, clean, in that window's frame), for long sequences sampled in several batches of
    windows. Window 0's overlap is then in-painted towards it: ``x[0, :overlap] += signal * (known -
    x0_hat[0, :overlap])`` (x0_hat 0 before the first step), ``known`` the prefix in window 0's frame, so
    the sample keeps its noise and takes the known clean part. ``base``: the frame of the window the prefix
    belongs to, relative to the global frame (:meth:`to_global`).

    ``anchors``: window frames known before sampling, (B, K) with NaN where a number is not known: window
    b's frame relative to window b - 1's (row 0: window 0's relative to the prefix window). A known number
    replaces the one read from x0_hat (EgoMusic: the heading turned between two window starts, read from
    the egocentric video, so that the windows' headings do not drift with the sampled motion).

    Args:
        overlap: frames shared by consecutive windows.
        relative: the per-window-relative channel mask, or None.
        frames: the windows' frames (instead of ``relative``).
        prefix: (overlap, ...) the clean motion window 0 continues, or None.
        base: (1, K) the prefix window's global frame (None: identity).
        inpaint_last: in-paint after the last step too.
        anchors: (B, K) known relative frames, NaN where unknown, or None.
        inpaint: False: in-paint nothing, only find each window's frame from the one before (the windows are
            then sampled each alone and joined by :func:`stitch_windows`' cross-fade alone).
    """

    def __init__(
        self,
        overlap: int,
        relative: torch.Tensor | None = None,
        frames: WindowFrames | None = None,
        prefix: torch.Tensor | None = None,
        base: torch.Tensor | None = None,
        inpaint_last: bool = False,
        anchors: torch.Tensor | None = None,
        inpaint: bool = True,
    ):
        if relative is not None and frames is not None:
            raise ValueError("give relative channels or window frames, not both")
        self.overlap = overlap
        self.frames = TranslationFrames(relative) if relative is not None else frames
        if prefix is not None and prefix.shape[0] != overlap:
            raise ValueError(f"the prefix has {prefix.shape[0]} frames, the overlap {overlap}")
        self.prefix = prefix
        self.base = base
        self.inpaint_last = inpaint_last
        if anchors is not None and frames is None:
            raise ValueError("anchors are window frames: give the windows' frames too")
        self.anchors = anchors
        self.inpaint = inpaint
        self.relative_frames: torch.Tensor | None = None  # (B, K) frame of window b in window b - 1's

    def _relative_frames(self, x: torch.Tensor, x0: torch.Tensor | None) -> torch.Tensor | None:
        """(B, K): window 0's relative to the prefix window (identity without one), window b's from x0."""
        if self.frames is None:
            return None
        frames = self.frames.identity(x.shape[0], x)
        if self.prefix is not None:
            frames[:1] = self.frames.relative_frame(self.prefix[:1].to(x.device, x.dtype))
        if x0 is not None and x.shape[0] > 1:
            frames[1:] = self.frames.relative_frame(x0[:-1, x.shape[1] - self.overlap])
        if self.anchors is not None:
            known = self.anchors.to(frames)
            frames = torch.where(known.isfinite(), known, frames)
        return frames

    def __call__(
        self, x: torch.Tensor, x0: torch.Tensor | None = None, signal: torch.Tensor | float = 1.0
    ) -> torch.Tensor:
        _check(x.shape[1], self.overlap)
        if self.overlap == 0:
            self.relative_frames = self._relative_frames(x, None)
            return x
        self.relative_frames = frames = self._relative_frames(x, x0)
        if not self.inpaint:
            return x
        scale = torch.as_tensor(signal, dtype=x.dtype, device=x.device).reshape(-1)
        if not self.inpaint_last and bool((scale == 1).all()):  # after the last step: keep the predictions
            return x
        scale = scale.expand(x.shape[0]).reshape(-1, *([1] * (x.ndim - 1)))
        hop = x.shape[1] - self.overlap
        x = x.clone()
        if self.prefix is not None:
            known = self.prefix[None].to(x.device, x.dtype)
            if frames is not None:
                known = self.frames.to_frame(known, frames[:1])
            clean = 0.0 if x0 is None else x0[:1, : self.overlap]
            x[:1, : self.overlap] = x[:1, : self.overlap] + scale[:1] * (known - clean)
        for b in range(1, x.shape[0]):
            tail = x[b - 1 : b, hop:]
            if frames is not None:
                tail = self.frames.to_frame(tail, frames[b : b + 1], scale[b])
            x[b, : self.overlap] = tail[0]
        return x

    def global_frames(self, count: int, like: torch.Tensor) -> torch.Tensor | None:
        """(count, K) every window's frame relative to the global one (None without frames)."""
        if self.frames is None:
            return None
        relative = self.relative_frames
        if relative is None:
            relative = self.frames.identity(count, like)
        frame = self.base if self.base is not None else self.frames.identity(1, like)
        out = []
        for b in range(count):
            frame = self.frames.compose(frame, relative[b : b + 1].to(frame))
            out.append(frame)
        return torch.cat(out)

    def to_global(self, windows: torch.Tensor) -> torch.Tensor:
        """(B, W, ...) windows in their own frames -> in the global frame (the first window's, or that of
        ``base``)."""
        frames = self.global_frames(windows.shape[0], windows)
        if frames is None:
            return windows
        return self.frames.from_frame(windows, frames.to(windows.dtype))


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
    sample_fn: Callable[[WindowConsistency, slice], torch.Tensor],
    overlap: int,
    total_frames: int | None = None,
    relative: torch.Tensor | None = None,
    *,
    frames: WindowFrames | None = None,
    num_windows: int | None = None,
    batch_windows: int | None = None,
    inpaint_last: bool = False,
    anchors: torch.Tensor | None = None,
    join: bool = True,
    inpaint: bool = True,
) -> torch.Tensor:
    """Sample a long sequence as windows kept consistent during sampling, then stitch them.

    ``sample_fn(post_step, windows)`` runs the sampler for the windows ``windows`` (a slice of the
    ``num_windows`` windows) with ``post_step`` (a :class:`WindowConsistency`: ``relative`` channels or
    ``frames`` as there) as its post-step projection, and returns them (n, W, ...). The windows are sampled
    in batches of at most ``batch_windows`` (None: all at once), so memory does not grow with the sequence;
    the first window of each later batch continues the last window of the batch before, sampled already
    (its tail is in-painted as a known ``prefix``). The windows are stitched, in window 0's frame, into
    one sequence of ``total_frames`` frames, their overlaps cross-faded (``inpaint_last``, ``anchors``
    (num_windows, K): as :class:`WindowConsistency`).

    ``inpaint=False``: the overlaps are not in-painted; each window's frame is still found from the one
    before, and the windows are joined by the cross-fade alone.

    ``join=False``: the same windows, drawn with the same noise (the same batches from the same generator),
    sampled each alone (nothing in-painted) and returned unjoined, (num_windows, W, ...) each in its own
    frame: what joining them changes, measured without the noise of another draw.
    """
    if num_windows is None:
        raise ValueError("sample_long needs num_windows (the windows sample_fn can sample)")
    if batch_windows is not None and batch_windows < 1:
        raise ValueError(f"batch_windows must be >= 1, got {batch_windows}")
    step = num_windows if batch_windows is None else batch_windows
    done: list[torch.Tensor] = []
    prefix = base = None
    for first in range(0, num_windows, step):
        which = slice(first, min(first + step, num_windows))
        if not join:
            done.append(sample_fn(_alone, which))
            continue
        known = None if anchors is None else anchors[which]
        consistency = WindowConsistency(
            overlap, relative, frames, prefix, base, inpaint_last, known, inpaint=inpaint
        )
        windows = sample_fn(consistency, which)
        done.append(consistency.to_global(windows))
        if overlap > 0 and consistency.frames is not None:
            base = consistency.global_frames(windows.shape[0], windows)[-1:]
        prefix = windows[-1, windows.shape[1] - overlap :] if overlap > 0 else None
    return stitch_windows(torch.cat(done), overlap, total_frames) if join else torch.cat(done)


def _alone(
    x: torch.Tensor, x0: torch.Tensor | None = None, signal: torch.Tensor | float = 1.0
) -> torch.Tensor:
    """The post-step of windows sampled alone: nothing in-painted."""
    return x
