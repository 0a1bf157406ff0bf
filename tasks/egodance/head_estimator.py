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

from dataclasses import dataclass

import torch
from torch import nn

from skeleton_mamba.tasks.egodance.frames import resize_frames
from skeleton_mamba.tasks.motion.rotations import rotation_6d_to_matrix

__all__ = [
    "HeadEstimatorConfig",
    "HeadTrajectoryEstimator",
    "head_trajectory_loss",
    "head_trajectory_errors",
    "estimate_long_trajectory",
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

    def frame_features(self, frames: torch.Tensor) -> torch.Tensor:
        """(B, T, 3, H, W) -> (B, T, dim): CNN of [frame_t, frame_t - frame_(t-1)]."""
        if frames.ndim != 5 or frames.shape[2] != 3:
            raise ValueError(f"expected frames (B, T, 3, H, W), got {tuple(frames.shape)}")
        b, t = frames.shape[:2]
        size = (self.config.input_size,) * 2
        small = resize_frames(frames.flatten(0, 1).float(), size).reshape(b, t, 3, *size)
        diff = torch.cat([torch.zeros_like(small[:, :1]), small[:, 1:] - small[:, :-1]], dim=1)
        x = torch.cat([small - 0.5, diff], dim=2).flatten(0, 1)
        feats = [self.cnn(x[i : i + self.config.chunk]) for i in range(0, x.shape[0], self.config.chunk)]
        return torch.cat(feats).reshape(b, t, -1)

    def forward(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Frames (B, T, 3, H, W) -> positions (B, T, 3) in metres, rotations (B, T, 3, 3) (head-to-world)."""
        h, _ = self.gru(self.frame_features(frames))
        out = self.head(h)
        return out[..., :3], rotation_6d_to_matrix(out[..., 3:])


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
    estimator: HeadTrajectoryEstimator, frames: torch.Tensor, window: int = 150
) -> tuple[torch.Tensor, torch.Tensor]:
    """A whole video (T, 3, H, W) -> positions (T, 3), rotations (T, 3, 3) in its first window's frame.

    Windows of ``window`` frames start every ``window - 1`` frames (the last one ends at the last frame) and
    are estimated independently, each in its own canonical frame; window k is then moved horizontally so that
    its first frame lands where window k - 1 put that frame (heights above the floor and world rotations need
    no chaining).
    """
    total = frames.shape[0]
    if total <= window:
        positions, rotations = estimator(frames[None])
        return positions[0], rotations[0]
    positions = frames.new_zeros(total, 3)
    rotations = frames.new_zeros(total, 3, 3)
    start = 0
    while True:
        start = min(start, total - window)
        pos, rot = estimator(frames[None, start : start + window])
        pos, rot = pos[0], rot[0]
        if start > 0:  # continue from the previous window's estimate of this window's first frame
            pos[:, [0, 2]] += positions[start, [0, 2]] - pos[0, [0, 2]]
        positions[start : start + window] = pos
        rotations[start : start + window] = rot
        if start + window >= total:
            return positions, rotations
        start += window - 1
