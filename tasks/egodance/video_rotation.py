"""The head's rotation read from the egocentric video itself: photometric alignment of frames by kornia.

A camera that turns without moving maps pixel x of frame t to ``x' ~ K R K^-1 x`` in frame t + k, where
``R = R_{t+k}^T R_t`` is the relative rotation of the camera-to-world rotations and ``K`` the intrinsics. The
head-mounted camera moves a little too (a dancer's head sways centimetres, the room is metres away), so the
rotation that best aligns two frames under this homography is their relative rotation up to a small
parallax error. :func:`align_rotations` finds it for a batch of frame pairs: ``kornia.geometry``'s
perspective warp of the first frame by ``K R K^-1`` against the second, a robust L1 photometric error over the
pixels both see, minimised over R's axis-angle by L-BFGS, coarse to fine (Gaussian-blurred, then sharp).
Whole-image alignment needs no features: the demo's frames are 32 px, and kornia's learned matchers need
weights downloaded at run time; it aligns the frames to a fraction of a pixel.

:class:`HeadRotationStream` tracks a whole video as it is decoded: every frame against the one before (small
rotations, found from rest), then every ``keyframe``-th frame against the keyframe before it, starting from
the frame-to-frame chain and refined, and the chain between keyframes corrected to end where the keyframe
alignment does. Chaining frame to frame alone drifts (a bias of a few hundredths of a degree per pair adds up
to tens of degrees a minute); keyframes a second apart hold it to about a degree a minute on the demo's
videos (``tests/tasks/egodance/test_video_rotation.py`` tracks a rendered video with a known head path).

:func:`head_headings` turns the camera rotations into the head's heading (radians about the vertical, relative
to frame 0), what anchors each long-form window's heading (:mod:`.long_form`).
"""

from __future__ import annotations

import math

import kornia
import numpy as np
import torch

__all__ = [
    "HeadRotationStream",
    "align_rotations",
    "alignment_residual",
    "head_headings",
    "intrinsics_for",
    "scale_intrinsics",
]

KEYFRAME = 30
"""Frames between keyframes (a second at 30 fps)."""

MIN_EXPLAINED = 0.8
"""Share of consecutive frame pairs a rotation must explain for the video's reading to be used."""

EXPLAINED_FRACTION = 0.5
"""A pair is explained when the residual left by its rotation is at most this fraction of the frame's own
spread about its mean grey level (both robust L1, :func:`alignment_residual`)."""

SCALES = (2.0, 1.0, 0.0)
"""Gaussian blur sigmas (pixels) of the coarse-to-fine alignment; 0: the frames as they are."""


def intrinsics_for(size: int, fov_x_deg: float = 90.0, aspect: float = 1.0) -> torch.Tensor:
    """(3, 3) intrinsics of frames resized to ``size`` x ``size`` from a camera of horizontal field of view
    ``fov_x_deg`` whose frames were ``aspect`` = width / height before the resize (square pixels then, so
    the vertical focal length is ``aspect`` times the horizontal one after it)."""
    if not 0 < fov_x_deg < 180:
        raise ValueError(f"the horizontal field of view must lie in (0, 180) degrees, got {fov_x_deg}")
    fx = (size / 2) / math.tan(math.radians(fov_x_deg) / 2)
    return torch.tensor([[fx, 0.0, size / 2], [0.0, fx * aspect, size / 2], [0.0, 0.0, 1.0]])


def scale_intrinsics(K: torch.Tensor, sx: float, sy: float) -> torch.Tensor:
    """(3, 3) intrinsics of frames resized by ``sx`` horizontally and ``sy`` vertically."""
    return K.float() * torch.tensor([sx, sy, 1.0])[:, None]


def _blur(images: torch.Tensor, sigma: float) -> torch.Tensor:
    if sigma <= 0:
        return images
    size = 2 * round(3 * sigma) + 1
    return kornia.filters.gaussian_blur2d(images, (size, size), (sigma, sigma))


def _robust(difference: torch.Tensor) -> torch.Tensor:
    """The robust L1 penalty of a difference: ``sqrt(d^2 + 1e-4)`` (a floor of 0.01 where it is 0)."""
    return (difference**2 + 1e-4).sqrt()


def _warp(first: torch.Tensor, homography: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``first`` (N, 1, H, W) warped by ``homography`` (N, 3, 3), and the bool mask of the pixels it
    covers."""
    size = tuple(first.shape[-2:])
    predicted = kornia.geometry.transform.warp_perspective(first, homography, size, align_corners=False)
    seen = kornia.geometry.transform.warp_perspective(
        torch.ones_like(first), homography, size, align_corners=False
    )
    return predicted, seen > 0.999


def align_rotations(
    first: torch.Tensor,
    second: torch.Tensor,
    K: torch.Tensor,
    init: torch.Tensor | None = None,
    iterations: int = 40,
) -> torch.Tensor:
    """Relative rotations ``R`` (N, 3, 3) with ``second ~ warp(first, K R K^-1)`` (module docstring).

    Args:
        first: (N, 1, H, W) grey frames.
        second: (N, 1, H, W) the frames they are aligned to.
        K: (3, 3) intrinsics of both.
        init: (N, 3) axis-angle starting points (None: no rotation).
        iterations: L-BFGS iterations per scale of :data:`SCALES`.
    """
    n = first.shape[0]
    angles = (torch.zeros(n, 3) if init is None else init.detach().clone()).float().requires_grad_(True)
    K = K.float()
    k, k_inv = K.expand(n, 3, 3), torch.linalg.inv(K).expand(n, 3, 3)
    with torch.enable_grad():
        for sigma in SCALES:
            a, b = _blur(first.float(), sigma), _blur(second.float(), sigma)
            optimizer = torch.optim.LBFGS([angles], lr=1, max_iter=iterations, line_search_fn="strong_wolfe")

            def closure(a=a, b=b, optimizer=optimizer):
                optimizer.zero_grad()
                homography = k @ kornia.geometry.conversions.axis_angle_to_rotation_matrix(angles) @ k_inv
                predicted, seen = _warp(a, homography)
                loss = (_robust(predicted - b) * seen).sum() / n  # robust L1 where both see
                loss.backward()
                return loss

            optimizer.step(closure)
    return kornia.geometry.conversions.axis_angle_to_rotation_matrix(angles.detach())


@torch.no_grad()
def alignment_residual(
    first: torch.Tensor, second: torch.Tensor, K: torch.Tensor, R: torch.Tensor
) -> torch.Tensor:
    """(N,) the mean robust photometric residual of ``second`` against ``first`` warped by ``K R K^-1`` over
    the pixels both see (infinite where they share less than a third of the frame): which of two rotations
    explains a pair of frames better."""
    predicted, seen = _warp(first.float(), K.float() @ R.float() @ torch.linalg.inv(K.float()))
    seen = seen.flatten(1).float()
    residual = (_robust(predicted - second.float()).flatten(1) * seen).sum(1) / seen.sum(1).clamp_min(1)
    return torch.where(seen.mean(1) >= 1 / 3, residual, torch.full_like(residual, float("inf")))


def _grey(frames: torch.Tensor, size: int) -> torch.Tensor:
    """(N, 3, H, W) RGB in [0, 1] -> (N, 1, size, size) grey."""
    grey = kornia.color.rgb_to_grayscale(frames.float())
    if grey.shape[-1] != size or grey.shape[-2] != size:
        grey = torch.nn.functional.interpolate(grey, size=(size, size), mode="area")
    return grey


def _fraction(rotation: torch.Tensor, fraction: torch.Tensor) -> torch.Tensor:
    """(3, 3) rotation -> (F, 3, 3) the same rotation scaled to each ``fraction`` of its angle."""
    axis_angle = kornia.geometry.conversions.rotation_matrix_to_axis_angle(rotation[None])[0]
    return kornia.geometry.conversions.axis_angle_to_rotation_matrix(fraction[:, None] * axis_angle)


class HeadRotationStream:
    """Tracks the camera's rotation through a video pushed chunk by chunk (module docstring): it keeps the
    frame-to-frame rotations and the keyframes' small grey frames (one a second), never the video.

    Args:
        K: (3, 3) intrinsics of the frames after they are resized to ``size`` (:func:`intrinsics_for`).
        size: frames are aligned at ``size`` x ``size`` grey pixels.
        keyframe: frames between keyframes (:data:`KEYFRAME`).
        step_iterations: L-BFGS iterations per scale for consecutive frames (their rotations are small, and
            the keyframes correct what they miss).
        batch: frames held before they are aligned together (L-BFGS on a batch is much faster than on
            the few frames of one decoded chunk).
    """

    def __init__(
        self,
        K: torch.Tensor,
        size: int,
        keyframe: int = KEYFRAME,
        step_iterations: int = 15,
        batch: int = 256,
    ):
        if keyframe < 1:
            raise ValueError(f"keyframe must be >= 1 frame, got {keyframe}")
        self.K, self.size, self.keyframe, self.batch = K, size, keyframe, batch
        self.step_iterations = step_iterations
        self.steps: list[torch.Tensor] = []  # (3, 3) frame t -> t + 1: R_{t+1}^T R_t
        self.key_frames: list[torch.Tensor] = []  # (1, size, size) grey frames 0, keyframe, 2 keyframe, ...
        self.pending: list[torch.Tensor] = []  # grey frames not aligned yet (and the last one aligned)
        self.count = 0
        self.explained = 0  # consecutive pairs a rotation explains (:attr:`reliable`)

    @torch.no_grad()
    def push(self, frames: torch.Tensor) -> None:
        """The next frames (N, 3, H, W) of the video, RGB in [0, 1], in order."""
        if len(frames) == 0:
            return
        grey = _grey(frames, self.size)
        first = -(-self.count // self.keyframe) * self.keyframe
        self.key_frames.extend(
            grey[i - self.count] for i in range(first, self.count + len(grey), self.keyframe)
        )
        self.count += len(grey)
        self.pending.extend(grey)
        if len(self.pending) > self.batch:
            self._align_pending()

    def _align_pending(self) -> None:
        """Align the frames held since the last alignment with the frame before each (one batch)."""
        if len(self.pending) > 1:
            pairs = torch.stack(self.pending)
            first, second = pairs[:-1], pairs[1:]
            steps = align_rotations(first, second, self.K, iterations=self.step_iterations)
            self.steps.extend(steps)
            aligned = alignment_residual(first, second, self.K, steps)
            # explained: what is left after the rotation is small against how much the frame itself varies
            # (noise frames are left with as much as they vary; a covered lens varies by nothing)
            flat = second.flatten(1)
            contrast = _robust(flat - flat.mean(1, keepdim=True)).mean(1)
            self.explained += int((aligned <= EXPLAINED_FRACTION * contrast).sum())
        self.pending = self.pending[-1:]

    @property
    def reliable(self) -> bool:
        """Whether a rotation explains most frame pairs (:data:`MIN_EXPLAINED`): false for frames that do
        not show one rigid scene turning (noise, cuts, a covered lens), whose readings mean nothing."""
        return len(self.steps) == 0 or self.explained >= MIN_EXPLAINED * len(self.steps)

    def _chain(self, start: int, end: int) -> torch.Tensor:
        """(end - start + 1, 3, 3): frame ``start`` -> each frame up to ``end`` (``R_t^T R_start``),
        chained."""
        out = [torch.eye(3)]
        for step in self.steps[start:end]:
            out.append(step @ out[-1])
        return torch.stack(out)

    @torch.no_grad()
    def finish(self) -> torch.Tensor:
        """(T, 3, 3): each frame's camera rotation relative to frame 0's (camera t's axes in camera 0's:
        ``R_0^T R_t``)."""
        if self.count == 0:
            raise ValueError("no frames were pushed")
        self._align_pending()
        bounds = list(range(0, self.count, self.keyframe))
        if bounds[-1] != self.count - 1:
            bounds.append(self.count - 1)
        chains = [self._chain(a, b) for a, b in zip(bounds[:-1], bounds[1:])]
        keys = [k for k in range(1, len(self.key_frames)) if k * self.keyframe < self.count]
        if keys:  # every keyframe against the one before, in one batch, from the chain between them
            chained = torch.stack([chains[k - 1][-1] for k in keys])
            init = kornia.geometry.conversions.rotation_matrix_to_axis_angle(chained)
            first = torch.stack([self.key_frames[k - 1] for k in keys])
            second = torch.stack([self.key_frames[k] for k in keys])
            aligned = align_rotations(first, second, self.K, init)
            better = alignment_residual(first, second, self.K, aligned) <= alignment_residual(
                first, second, self.K, chained
            )
            for k, rotation, keep in zip(keys, aligned, better):
                if keep:  # else the alignment went astray: the chain explains the keyframes better
                    chain = chains[k - 1]
                    correction = rotation @ chain[-1].T
                    chains[k - 1] = _fraction(correction, torch.linspace(0, 1, len(chain))) @ chain
        out = torch.eye(3).repeat(self.count, 1, 1)
        for (start, end), chain in zip(zip(bounds[:-1], bounds[1:]), chains):
            # camera t in camera 0's axes: R_0^T R_t = (R_0^T R_start)(R_start^T R_t) = out[start] chain_t^T
            out[start : end + 1] = out[start] @ chain.transpose(1, 2)
        return out


def head_headings(camera: torch.Tensor) -> torch.Tensor:
    """(T, 3, 3) camera rotations relative to frame 0 (:meth:`HeadRotationStream.finish`) -> (T,)
    the head's heading change since frame 0 (radians, about the vertical, positive as
    :func:`.heading_frames.head_heading`: from +z towards +x), unwrapped. The vertical is taken as frame 0's
    camera up (a camera within a few degrees of level; its pitch scales the turn by its cosine)."""
    forward = camera[:, :, 2]  # camera t's optical axis in camera 0's axes (x right, y down, z forward)
    # the head's frame is the camera's with x and y flipped (x left, y up): its heading is atan2(-x, z)
    heading = torch.atan2(-forward[:, 0], forward[:, 2])
    return torch.from_numpy(np.unwrap(heading.double().numpy()))
