"""Window frames: how a task's long-form windows relate when each is expressed in a frame of its own.

A task trained on windows canonicalised at their first frame (the root at the origin; with EgoMusic's
``canonicalize_init_head`` also turned to face the head's heading) expects every window it samples to start
in that frame. Long-form sampling (:mod:`.stitching`) therefore expresses the overlap that window b shares
with window b - 1 in window b's own frame, which is found from window b - 1's motion at the frame where
window b starts. A :class:`WindowFrames` object says how: which rigid motion relates the two frames
(:meth:`~WindowFrames.relative_frame`), how a motion moves into a frame and back
(:meth:`~WindowFrames.to_frame`, :meth:`~WindowFrames.from_frame`), and how frames compose
(:meth:`~WindowFrames.compose`) to bring every window into window 0's frame.

Noisy samples: ``x = signal * x0 + noise``, and every transform here is ``x -> L x + t`` with ``L`` an
orthogonal map of some channels (a rotation) and ``t`` a translation. Applied to a noisy sample as
``L x + signal * t`` it maps ``signal * x0 + noise`` to ``signal * (L x0 + t) + L noise``: the transformed
clean motion at the same noise level, with noise ``L noise`` that is again white (an orthogonal map of
white Gaussian noise). ``to_frame(x, frame, signal)`` takes that ``signal``.

Frames are tensors of shape (B, K) (K numbers per window, the task's parametrisation); the identity frame is
:meth:`~WindowFrames.identity`.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import torch

__all__ = ["WindowFrames", "TranslationFrames"]


@runtime_checkable
class WindowFrames(Protocol):
    """The frames of long-form windows (module docstring). ``x`` is (B, n, ...) motion, frames (B, K)."""

    def identity(self, batch: int, like: torch.Tensor) -> torch.Tensor:
        """(B, K) identity frames."""

    def relative_frame(self, first: torch.Tensor) -> torch.Tensor:
        """(B, ...) one clean frame of motion, in a window's frame -> (B, K): the frame of the window that
        starts there, relative to that window's frame."""

    def to_frame(
        self, x: torch.Tensor, frame: torch.Tensor, signal: torch.Tensor | float = 1.0
    ) -> torch.Tensor:
        """Motion (B, n, ...) given in the parent frame -> in ``frame`` (B, K) (relative to the parent);
        translations scaled by ``signal`` (a noisy sample's sqrt(alpha_bar); module docstring)."""

    def from_frame(self, x: torch.Tensor, frame: torch.Tensor) -> torch.Tensor:
        """The inverse of :meth:`to_frame` for clean motion (signal 1): motion in ``frame`` -> its parent."""

    def compose(self, outer: torch.Tensor, inner: torch.Tensor) -> torch.Tensor:
        """The frame ``inner`` (relative to ``outer``) relative to ``outer``'s parent:
        ``from_frame(from_frame(x, inner), outer) == from_frame(x, compose(outer, inner))``."""


class TranslationFrames:
    """Frames that differ by a translation of some channels: the frame of a window starting at motion
    frame ``f`` is ``relative * f`` (e.g. the root's horizontal position, 0 at a window's first frame).

    Args:
        relative: (...) mask (broadcastable to one motion frame) of the channels holding positions relative
            to the window's first frame; frames are those channels' values (K = the frame's element count).
    """

    def __init__(self, relative: torch.Tensor):
        self.relative = relative

    def _offset(self, frame: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
        """(B, K) -> (B, 1, ...) offsets broadcast over frames."""
        return frame.reshape(frame.shape[0], 1, *like.shape[2:]).to(like.dtype)

    def identity(self, batch: int, like: torch.Tensor) -> torch.Tensor:
        return like.new_zeros(batch, like[0, 0].numel())

    def relative_frame(self, first: torch.Tensor) -> torch.Tensor:
        return (first * self.relative.to(first.device, first.dtype)).reshape(first.shape[0], -1)

    def to_frame(
        self, x: torch.Tensor, frame: torch.Tensor, signal: torch.Tensor | float = 1.0
    ) -> torch.Tensor:
        return x - _per_window(signal, x) * self._offset(frame, x)

    def from_frame(self, x: torch.Tensor, frame: torch.Tensor) -> torch.Tensor:
        return x + self._offset(frame, x)

    def compose(self, outer: torch.Tensor, inner: torch.Tensor) -> torch.Tensor:
        return outer + inner


def _per_window(signal: torch.Tensor | float, x: torch.Tensor) -> torch.Tensor:
    """A scalar or per-window (B, ...) signal level -> (B, 1, ..., 1) broadcastable to x (B, n, ...)."""
    s = torch.as_tensor(signal, dtype=x.dtype, device=x.device).reshape(-1)
    return s.expand(x.shape[0]).reshape(-1, *([1] * (x.ndim - 1)))
