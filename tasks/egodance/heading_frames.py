"""The frames of EMM windows for long-form sampling (:mod:`skeleton_mamba.tasks.training.diffusion`'s
``window_frames``).

Training windows are canonicalised at their first frame (:mod:`.data`): the root's horizontal position is
moved to x = z = 0, and with ``canonicalize_init_head`` the window is also turned about the vertical so that
the head joint faces +z (the heading of its forward axis, :func:`head_heading`). A window that starts at frame
``s`` of the window before it therefore lives in the frame whose origin is that window's root at ``s`` (on the
floor) and whose +z is its head's heading at ``s``: :class:`HeadingFrames` finds that frame from the motion
and moves motion tokens into it and back. Only the root joint's tokens change: its global orientation
(6D, both columns turned) and its position; every other joint's rotation is relative to its parent, and
contacts do not depend on the frame. With ``turn=False`` (windows that keep the world yaw) the frames are
the horizontal translations alone.

A frame is (B, 3): ``(theta, x, z)``, the heading and the origin's horizontal position in the parent frame:
``from_frame(u) = Y(theta) u + (x, 0, z)`` for positions, ``Y(theta) R`` for the root's orientation, with
``Y`` the rotation about +y (:func:`yaw_matrices`, the builder's ``yaw_matrix``).
"""

from __future__ import annotations

import torch

from skeleton_mamba.tasks.egodance.representation import HEAD_JOINT, ROOT, ROT
from skeleton_mamba.tasks.motion.body.rotations import rotation_6d_to_matrix

Signal = torch.Tensor | float  # a noisy sample's sqrt(alpha_bar): a number or one per window

__all__ = [
    "HEAD_CHAIN",
    "HeadingFrames",
    "head_heading",
    "head_rotation",
    "relative_headings",
    "yaw_matrices",
]

HEAD_CHAIN = (0, 3, 6, 9, 12, HEAD_JOINT)
"""SMPL-24 joints from the pelvis to the head (pelvis, spine1-3, neck, head)."""


def yaw_matrices(theta: torch.Tensor) -> torch.Tensor:
    """(...) angles (radians) -> (..., 3, 3) rotations about +y (x -> -z for +90 degrees)."""
    c, s = theta.cos(), theta.sin()
    zero, one = torch.zeros_like(theta), torch.ones_like(theta)
    rows = [torch.stack([c, zero, s], -1), torch.stack([zero, one, zero], -1), torch.stack([-s, zero, c], -1)]
    return torch.stack(rows, -2)


def head_heading(rotation: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) head-to-world rotations -> (...) heading (radians about +y) of the head's forward axis (its
    local +z): ``yaw_matrices(-heading)`` turns that axis onto +z (the canonical frame's forward)."""
    forward = rotation[..., :, 2]
    return torch.atan2(forward[..., 0], forward[..., 2])


def relative_headings(rotation: torch.Tensor) -> torch.Tensor:
    """(..., T, 3, 3) head-to-world rotations -> (..., T) the head's heading (radians about +y) relative to
    frame 0's, wrapped to [-pi, pi): how far the head has turned since the first frame."""
    heading = head_heading(rotation)
    return torch.remainder(heading - heading[..., :1] + torch.pi, 2 * torch.pi) - torch.pi


def head_rotation(tokens: torch.Tensor) -> torch.Tensor:
    """(..., 24, 10) motion tokens -> (..., 3, 3) the head joint's global rotation (the product of the local
    rotations along :data:`HEAD_CHAIN`)."""
    local = rotation_6d_to_matrix(tokens[..., list(HEAD_CHAIN), ROT])
    out = local[..., 0, :, :]
    for k in range(1, len(HEAD_CHAIN)):
        out = out @ local[..., k, :, :]
    return out


class HeadingFrames:
    """:class:`~skeleton_mamba.tasks.training.diffusion.window_frames.WindowFrames` of EMM windows
    (module docstring).

    Args:
        turn: windows face their first frame's head heading (``canonicalize_init_head``); False: the frames
            differ by horizontal translations only.
    """

    def __init__(self, turn: bool = True):
        self.turn = turn

    def identity(self, batch: int, like: torch.Tensor) -> torch.Tensor:
        return like.new_zeros(batch, 3)

    def relative_frame(self, first: torch.Tensor) -> torch.Tensor:
        """(B, 24, 10) the first frame of the next windows, in the parent frame -> (B, 3) their frames."""
        theta = head_heading(head_rotation(first)) if self.turn else first.new_zeros(first.shape[0])
        root = first[:, 0, ROOT]
        return torch.stack([theta, root[:, 0], root[:, 2]], -1)

    def _move(self, x: torch.Tensor, theta: torch.Tensor, shift: torch.Tensor) -> torch.Tensor:
        """Root orientation and position of x (B, n, 24, 10) turned by ``Y(theta)`` (B,), then the position
        moved by ``shift`` (B, 3)."""
        turn = yaw_matrices(theta).to(x.dtype)[:, None]  # (B, 1, 3, 3)
        out = x.clone()
        root = x[:, :, 0]
        for part in (slice(ROT.start, ROT.start + 3), slice(ROT.start + 3, ROT.stop), ROOT):
            out[:, :, 0, part] = (turn @ root[..., part, None])[..., 0]
        out[:, :, 0, ROOT] = out[:, :, 0, ROOT] + shift[:, None].to(x.dtype)
        return out

    def _origin(self, frame: torch.Tensor) -> torch.Tensor:
        """(B, 3) frames -> (B, 3) their origins (x, 0, z)."""
        zero = torch.zeros_like(frame[:, 0])
        return torch.stack([frame[:, 1], zero, frame[:, 2]], -1)

    def to_frame(self, x: torch.Tensor, frame: torch.Tensor, signal: Signal = 1.0) -> torch.Tensor:
        """``Y(-theta) (p - signal * o)`` for positions, ``Y(-theta) R`` for the root's orientation."""
        scale = torch.as_tensor(signal, dtype=x.dtype, device=x.device).reshape(-1)[:, None]
        turn = yaw_matrices(-frame[:, 0]).to(x.dtype)  # (B, 3, 3)
        shift = -(turn @ (scale * self._origin(frame).to(x.dtype))[..., None])[..., 0]
        return self._move(x, -frame[:, 0], shift)

    def points_to_frame(self, points: torch.Tensor, frame: torch.Tensor) -> torch.Tensor:
        """Positions (B, n, 3) in the parent frame -> in ``frame`` (B, 3): ``Y(-theta) (p - o)``."""
        turn = yaw_matrices(-frame[:, 0]).to(points.dtype)[:, None]
        return (turn @ (points - self._origin(frame)[:, None].to(points.dtype))[..., None])[..., 0]

    def from_frame(self, x: torch.Tensor, frame: torch.Tensor) -> torch.Tensor:
        return self._move(x, frame[:, 0], self._origin(frame))

    def compose(self, outer: torch.Tensor, inner: torch.Tensor) -> torch.Tensor:
        """``(theta_o + theta_i, Y(theta_o) o_i + o_o)``."""
        turned = (yaw_matrices(outer[:, 0]) @ self._origin(inner)[..., None])[..., 0]
        origin = turned + self._origin(outer)
        return torch.stack([outer[:, 0] + inner[:, 0], origin[:, 0], origin[:, 2]], -1)
