"""The head's trajectory from the egocentric frames alone, for head guidance without ground truth.

[EgoMusic] guides sampling with the head trajectory (supp. Sec. 6.3, G_head); the authors' code takes it
from [DROID-SLAM] run on the egocentric video. A user's video has no ground-truth camera, so this module
estimates the trajectory of the SMPL head joint (15) -- position (T, 3) and orientation (T, 3, 3) per frame --
in the canonical frame of the training windows (floor at y = 0, root at x = z = 0 in frame 0, world yaw
kept, or the head facing +z in frame 0 with ``canonicalize_init_head``; :mod:`.data`), the frame
:class:`.guidance.HeadGuidance` expects its targets in.

Design (ours; justified against the alternatives):

- *Learned, not geometric.* Monocular visual odometry (OpenCV essential matrices on tracked features)
  gives the rotation and the translation *direction* only: the scale, the gravity direction and the
  height above the floor -- which set where the head goes in metres -- need a learned step anyway, and
  feature tracking fails on the textureless, low-resolution and motion-blurred frames of dance videos
  ([EgoMusic] supp. Sec. 7.3: motion blur is its first failure case). DROID-SLAM needs a GPU and
  weights that are not available here. A small network trained on EgoAIST++ windows, whose camera paths
  are known by construction (``sm make-ego``), learns metric scale, gravity and floor height directly.
- *Appearance + temporal difference per frame.* Each frame (resized to ``input_size``) is stacked with its
  difference to the previous frame (zero for frame 0): the frame carries the absolute cues (floor and walls:
  height, pitch and roll, the room's yaw), the difference carries the ego-motion (what optical flow
  carries in the authors' vision input). A small CNN maps the 6 channels to one feature per frame. The
  pretrained ResNet of the EMM vision encoder is not reused: its pooled feature is built to be invariant to
  the small image shifts that encode head motion.
- *Bidirectional GRU over time*, then per frame the head position and a 6D rotation ([Rot6D];
  :func:`rotation_6d_to_matrix`). Positions are regressed directly, not integrated from per-frame steps: a
  dancer stays near the start, and in a first trial on synthetic EgoAIST++ windows integrated steps were
  off by 1.3-1.5 m after 150 frames (a small per-frame bias summed), while the whole-window context of
  the bidirectional GRU gives the displacement from the start directly. Videos longer than the training
  window are estimated window by window and chained (:func:`estimate_long_trajectory`).

Training (in :class:`.module.EgoDanceModule`, with its own parameters and loss, so the EMM's gradients are
untouched): the mean squared position error in units of ``position_scale`` (0.1 m: head errors of a few
centimetres then weigh as much as rotation errors of tens of degrees) plus ``rotation_weight`` times the
squared chordal distance ``||R_hat - R||_F^2``. Reported errors: mean Euclidean position error (mm) and
mean geodesic angle (deg).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import torch
from torch import nn

from skeleton_mamba.tasks.egodance.frames import resize_frames
from skeleton_mamba.tasks.motion.body.rotations import rotation_6d_to_matrix

__all__ = [
    "HeadEstimatorConfig",
    "HeadTrajectoryEstimator",
    "head_trajectory_loss",
    "head_trajectory_errors",
    "estimate_long_trajectory",
    "estimate_window_trajectories",
    "long_window_starts",
    "HeadFrameFeatures",
    "HeadFeatureStream",
]


@dataclass
class HeadEstimatorConfig:
    """Settings of :class:`HeadTrajectoryEstimator`.

    Attributes:
        input_size: frames are resized to (input_size, input_size).
        channels: widths of the stride-2 convolutions of the per-frame CNN (multiples of 8: GroupNorm).
        dim: per-frame feature and GRU hidden width.
        layers: GRU layers (bidirectional).
        position_scale: the position error is measured in these units (metres) in the loss.
        rotation_weight: weight of the squared chordal rotation error in the loss.
        chunk: frames per CNN call (bounds memory on long videos).
    """

    input_size: int = 64
    channels: tuple[int, ...] = (32, 64, 96, 128)
    dim: int = 128
    layers: int = 2
    position_scale: float = 0.1
    rotation_weight: float = 1.0
    chunk: int = 512


class HeadTrajectoryEstimator(nn.Module):
    """Egocentric frames (B, T, 3, H, W) in [0, 1] -> head positions (B, T, 3) and rotations (B, T, 3, 3)."""

    def __init__(self, config: HeadEstimatorConfig | None = None):
        super().__init__()
        self.config = cfg = config or HeadEstimatorConfig()
        layers, width = [], 6
        for out in cfg.channels:
            layers += [nn.Conv2d(width, out, 3, stride=2, padding=1), nn.GroupNorm(8, out), nn.GELU()]
            width = out
        self.cnn = nn.Sequential(*layers, nn.AdaptiveAvgPool2d(1), nn.Flatten(), nn.Linear(width, cfg.dim))
        self.gru = nn.GRU(cfg.dim, cfg.dim, cfg.layers, batch_first=True, bidirectional=True)
        self.head = nn.Linear(2 * cfg.dim, 3 + 6)  # position, rot6d
        with torch.no_grad():  # start at the identity rotation, 1.6 m above the start
            self.head.weight.mul_(0.01)
            self.head.bias.copy_(torch.tensor([0.0, 1.6, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]))

    def small_frames(self, frames: torch.Tensor) -> torch.Tensor:
        """(N, 3, H, W) -> (N, 3, s, s) float, s = ``input_size``: what the CNN sees of each frame."""
        return resize_frames(frames.float(), (self.config.input_size,) * 2)

    def cnn_features(self, small: torch.Tensor, diff: torch.Tensor) -> torch.Tensor:
        """Small frames (N, 3, s, s) and their differences to the previous frame (N, 3, s, s) -> (N, dim),
        in calls of at most ``chunk`` frames (each frame's feature depends on that frame's pair only)."""
        x = torch.cat([small - 0.5, diff], dim=1)
        feats = [self.cnn(x[i : i + self.config.chunk]) for i in range(0, x.shape[0], self.config.chunk)]
        return torch.cat(feats)

    def frame_features(self, frames: torch.Tensor) -> torch.Tensor:
        """(B, T, 3, H, W) -> (B, T, dim): CNN of [frame_t, frame_t - frame_(t-1)] (zero difference at
        t = 0)."""
        if frames.ndim != 5 or frames.shape[2] != 3:
            raise ValueError(f"expected frames (B, T, 3, H, W), got {tuple(frames.shape)}")
        b, t = frames.shape[:2]
        small = self.small_frames(frames.flatten(0, 1)).unflatten(0, (b, t))
        diff = torch.cat([torch.zeros_like(small[:, :1]), small[:, 1:] - small[:, :-1]], dim=1)
        return self.cnn_features(small.flatten(0, 1), diff.flatten(0, 1)).reshape(b, t, -1)

    def trajectory(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-frame features (B, T, dim) (:meth:`frame_features`) -> positions (B, T, 3) in metres,
        rotations (B, T, 3, 3) (head-to-world): the bidirectional GRU and the output layer."""
        h, _ = self.gru(features)
        out = self.head(h)
        return out[..., :3], rotation_6d_to_matrix(out[..., 3:])

    def forward(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Frames (B, T, 3, H, W) -> positions (B, T, 3) in metres, rotations (B, T, 3, 3) (head-to-world)."""
        return self.trajectory(self.frame_features(frames))


def long_window_starts(total: int, window: int) -> list[int]:
    """Start frames of the windows :func:`estimate_long_trajectory` estimates a ``total``-frame video in:
    every ``window - 1`` frames, the last one ending at the last frame (one window if ``total <= window``)."""
    if window < 2 and total > window:
        raise ValueError(f"long videos need a window of at least 2 frames, got {window}")
    starts = [0]
    while starts[-1] + window < total:
        starts.append(min(starts[-1] + window - 1, total - window))
    return starts


@dataclass
class HeadFrameFeatures:
    """A video's per-frame CNN features for :func:`estimate_long_trajectory`, without its frames.

    The CNN of frame t sees [frame_t, frame_t - frame_(t-1)], except at the first frame of an estimation
    window, where the difference is zero (:meth:`HeadTrajectoryEstimator.frame_features` of the window).

    Attributes:
        features: (T, dim): frame t with its difference to frame t - 1 (zero for frame 0).
        window_first: {start: (dim,)} frame ``start`` with a zero difference, for every window start of
            :func:`long_window_starts` (``window``) but 0, and every multiple of the stream's other ``hops``.
        window: the estimation window the features were prepared for.
    """

    features: torch.Tensor
    window_first: dict[int, torch.Tensor]
    window: int

    def __len__(self) -> int:
        return self.features.shape[0]

    def window_features(self, start: int, length: int) -> torch.Tensor:
        """(length, dim): what :meth:`HeadTrajectoryEstimator.frame_features` gives frames
        ``start:start + length`` estimated as one window."""
        feats = self.features[start : start + length]
        if start > 0:
            feats = torch.cat([self.window_first[start][None].to(feats.dtype), feats[1:]])
        return feats


class HeadFeatureStream:
    """Builds :class:`HeadFrameFeatures` from a video's frames pushed chunk by chunk, in memory bounded by
    the window: it keeps the features (dim floats per frame) and the last ``window`` small frames (for the
    last window's start, known once the video ends), never the video.

    Args:
        estimator: the head-trajectory estimator (in eval mode).
        window: the window of the later :func:`estimate_long_trajectory` call.
        hops: other window hops whose starts (every multiple) are also kept, for
            :func:`estimate_window_trajectories` on the windows of long-form sampling.
    """

    def __init__(self, estimator: HeadTrajectoryEstimator, window: int = 150, hops: tuple[int, ...] = ()):
        self.estimator = estimator
        self.window = window
        self.other_hops = tuple(h for h in hops if h > 0)
        self.hops = tuple({h for h in (window - 1, *hops) if h > 0})
        self.count = 0
        self.features: list[torch.Tensor] = []
        self.window_first: dict[int, torch.Tensor] = {}
        self.recent: deque[torch.Tensor] = deque(maxlen=window)  # small frames (3, s, s)

    def _alone(self, small: torch.Tensor) -> torch.Tensor:
        """(N, 3, s, s) -> (N, dim): the CNN feature of frames with a zero difference."""
        return self.estimator.cnn_features(small, torch.zeros_like(small))

    @torch.no_grad()
    def push(self, frames: torch.Tensor) -> None:
        """The next frames (N, 3, H, W) of the video, in order."""
        if len(frames) == 0:
            return
        small = self.estimator.small_frames(frames)
        previous = small[:1] if not self.recent else self.recent[-1][None].to(small.dtype)
        diff = small - torch.cat([previous, small[:-1]])
        if self.count == 0:
            diff[0] = 0.0
        self.features.append(self.estimator.cnn_features(small, diff))
        starts = set()  # the starts k * hop, k >= 1, that fall in this chunk
        for hop in self.hops:
            first = -(-max(self.count, 1) // hop) * hop
            starts.update(range(first, self.count + len(small), hop))
        starts = sorted(starts)
        if starts:
            alone = self._alone(small[[s - self.count for s in starts]])
            self.window_first.update(zip(starts, alone, strict=True))
        self.recent.extend(small)
        self.count += len(small)

    @torch.no_grad()
    def finish(self) -> HeadFrameFeatures:
        """The features of all the frames pushed (at least one)."""
        if self.count == 0:
            raise ValueError("no frames were pushed")
        total = self.count
        starts = long_window_starts(total, self.window)[1:]
        missing = [s for s in starts if s not in self.window_first]
        if missing:  # the last window's start, total - window: among the last `window` frames, held
            held = list(self.recent)
            alone = self._alone(torch.stack([held[s - (total - len(held))] for s in missing]))
            self.window_first.update(zip(missing, alone, strict=True))
        kept = set(starts) | {s for h in self.other_hops for s in range(h, total, h)}
        window_first = {s: self.window_first[s] for s in sorted(kept)}
        return HeadFrameFeatures(torch.cat(self.features), window_first, self.window)


def head_trajectory_loss(
    positions: torch.Tensor,
    rotations: torch.Tensor,
    true_positions: torch.Tensor,
    true_rotations: torch.Tensor,
    rotation_weight: float = 1.0,
    position_scale: float = 0.1,
) -> torch.Tensor:
    """``mean ||(p_hat - p) / position_scale||^2 + rotation_weight * mean ||R_hat - R||_F^2``.

    Positions (B, T, 3) in metres, rotations (B, T, 3, 3).
    """
    pos = ((positions - true_positions) / position_scale).pow(2).sum(-1).mean()
    rot = (rotations - true_rotations).pow(2).sum((-2, -1)).mean()
    return pos + rotation_weight * rot


def head_trajectory_errors(
    positions: torch.Tensor,
    rotations: torch.Tensor,
    true_positions: torch.Tensor,
    true_rotations: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per sequence (B,): mean Euclidean position error (mm) and mean geodesic rotation error (degrees)."""
    pos = (positions - true_positions).norm(dim=-1).mean(-1) * 1000.0
    cos = ((rotations.transpose(-1, -2) @ true_rotations).diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0
    angle = torch.rad2deg(torch.arccos(cos.clamp(-1.0, 1.0)))
    return pos, angle.mean(-1)


@torch.no_grad()
def estimate_long_trajectory(
    estimator: HeadTrajectoryEstimator, frames: torch.Tensor | HeadFrameFeatures, window: int = 150
) -> tuple[torch.Tensor, torch.Tensor]:
    """A whole video (T, 3, H, W), or its :class:`HeadFrameFeatures` (streamed, :class:`HeadFeatureStream`)
    -> positions (T, 3), rotations (T, 3, 3) in its first window's frame.

    Windows of ``window`` frames start every ``window - 1`` frames (the last one ends at the last frame;
    :func:`long_window_starts`) and are estimated independently, each in its own canonical frame; window k
    is then moved horizontally so that its first frame lands where window k - 1 put that frame (heights
    above the floor and world rotations need no chaining). Features and frames give the same trajectory.
    """
    if isinstance(frames, HeadFrameFeatures):
        if frames.window != window:
            raise ValueError(
                f"the features were prepared for windows of {frames.window} frames, not {window}"
            )
        total, dtype = len(frames), torch.float32

        def estimate(start: int, length: int) -> tuple[torch.Tensor, torch.Tensor]:
            return estimator.trajectory(frames.window_features(start, length)[None])

    else:
        total, dtype = frames.shape[0], frames.dtype

        def estimate(start: int, length: int) -> tuple[torch.Tensor, torch.Tensor]:
            return estimator(frames[None, start : start + length])

    if total <= window:
        positions, rotations = estimate(0, total)
        return positions[0], rotations[0]
    positions = torch.zeros(total, 3, dtype=dtype)
    rotations = torch.zeros(total, 3, 3, dtype=dtype)
    for start in long_window_starts(total, window):
        pos, rot = estimate(start, window)
        pos, rot = pos[0], rot[0]
        if start > 0:  # continue from the previous window's estimate of this window's first frame
            pos[:, [0, 2]] += positions[start, [0, 2]] - pos[0, [0, 2]]
        positions[start : start + window] = pos
        rotations[start : start + window] = rot
    return positions, rotations


@torch.no_grad()
def estimate_window_trajectories(
    estimator: HeadTrajectoryEstimator,
    frames: torch.Tensor | HeadFrameFeatures,
    starts: list[int],
    window: int,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Each window's head trajectory in that window's own canonical frame (what the estimator was trained
    to give; :mod:`.heading_frames`): frames (T, 3, H, W) or their :class:`HeadFrameFeatures` (prepared with
    the windows' hop) -> positions (B, window, 3), rotations (B, window, 3, 3) for the windows starting at
    ``starts``. A window that runs past the video is estimated on the frames there are, and its last
    estimate repeated (as the music of such a window repeats its last frame).
    """
    if isinstance(frames, HeadFrameFeatures):
        total = len(frames)

        def estimate(start: int, length: int) -> tuple[torch.Tensor, torch.Tensor]:
            return estimator.trajectory(frames.window_features(start, length)[None])

    else:
        total = frames.shape[0]

        def estimate(start: int, length: int) -> tuple[torch.Tensor, torch.Tensor]:
            return estimator(frames[None, start : start + length])

    positions, rotations = [], []
    for start in starts:
        if not 0 <= start < total:
            raise ValueError(f"a window starts at frame {start}, outside the video's {total} frames")
        pos, rot = estimate(start, min(window, total - start))
        pad = window - pos.shape[1]
        positions.append(torch.cat([pos[0], pos[0, -1:].expand(pad, -1)]))
        rotations.append(torch.cat([rot[0], rot[0, -1:].expand(pad, -1, -1)]))
    return torch.stack(positions), torch.stack(rotations)
