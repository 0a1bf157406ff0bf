"""The head's trajectory from the egocentric frames alone, for head guidance without ground truth.

[EgoMusic] guides sampling with the head trajectory (supp. section 6.3, G_head); the authors' code takes it
from DROID-SLAM run on the egocentric video. A user's video has no ground-truth camera, so this module
estimates the trajectory of the SMPL head joint (15) -- position (T, 3) and orientation (T, 3, 3) per frame --
in the canonical frame of the training windows (floor at y = 0, root at x = z = 0 in frame 0, world yaw
kept; :mod:`.data`), the frame :class:`.guidance.HeadGuidance` expects its targets in.

Design (ours; justified against the alternatives):

- *Learned, not geometric.* Monocular visual odometry (OpenCV essential matrices on tracked features)
  gives the rotation and the translation *direction* only: the scale, the gravity direction and the
  height above the floor -- which set where the head goes in metres -- need a learned step anyway, and
  feature tracking fails on the textureless, low-resolution and motion-blurred frames of dance videos
  ([EgoMusic] supp. section 7.2 names blur as its main failure). DROID-SLAM needs a GPU and weights that
  are not available here. A small network trained on EgoAIST++ windows, whose camera paths are known by
  construction (``sm make-ego``), learns metric scale, gravity and floor height directly.
- *Appearance + temporal difference per frame.* Each frame (resized to ``input_size``) is stacked with its
  difference to the previous frame (zero for frame 0): the frame carries the absolute cues (floor and walls:
  height, pitch and roll, the room's yaw), the difference carries the ego-motion (what optical flow
  carries in the authors' vision input). A small CNN maps the 6 channels to one feature per frame. The
  pretrained ResNet of the EMM vision encoder is not reused: its pooled feature is built to be invariant to
  the small image shifts that encode head motion.
- *Bidirectional GRU over time*, then per frame: the head height ``y_t``, the horizontal step ``d_t`` and
  a 6D rotation (Zhou et al.; :func:`rotation_6d_to_matrix`). The horizontal position is the running sum
  ``(x, z)_t = sum_{s <= t} d_s`` (``d_0`` is the head's offset from the root in frame 0), so the model
  learns velocities, which transfer to videos of any length (``sm dance`` runs it on whole tracks).

Training (in :class:`.module.EgoDanceModule`, with its own parameters and loss, so the EMM's gradients are
untouched): mean squared position error (m^2) plus ``rotation_weight`` times the squared chordal distance
``||R_hat - R||_F^2``. Reported errors: mean Euclidean position error (mm) and mean geodesic angle (deg).
"""

from __future__ import annotations

from dataclasses import dataclass

import kornia
import torch
from torch import nn

from skeleton_mamba.tasks.motion.rotations import rotation_6d_to_matrix

__all__ = [
    "HeadEstimatorConfig",
    "HeadTrajectoryEstimator",
    "head_trajectory_loss",
    "head_trajectory_errors",
]


@dataclass
class HeadEstimatorConfig:
    """Settings of :class:`HeadTrajectoryEstimator`.

    Attributes:
        input_size: frames are resized to (input_size, input_size).
        channels: widths of the stride-2 convolutions of the per-frame CNN (multiples of 8: GroupNorm).
        dim: per-frame feature and GRU hidden width.
        layers: GRU layers (bidirectional).
        rotation_weight: weight of the squared chordal rotation error in the loss.
        chunk: frames per CNN call (bounds memory on long videos).
    """

    input_size: int = 64
    channels: tuple[int, ...] = (32, 64, 96, 128)
    dim: int = 128
    layers: int = 2
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
        self.head = nn.Linear(2 * cfg.dim, 1 + 2 + 6)  # height, horizontal step, rot6d
        with torch.no_grad():  # start at the identity rotation, 1.6 m high, standing still
            self.head.weight.mul_(0.01)
            self.head.bias.copy_(torch.tensor([1.6, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]))

    def frame_features(self, frames: torch.Tensor) -> torch.Tensor:
        """(B, T, 3, H, W) -> (B, T, dim): CNN of [frame_t, frame_t - frame_(t-1)]."""
        if frames.ndim != 5 or frames.shape[2] != 3:
            raise ValueError(f"expected frames (B, T, 3, H, W), got {tuple(frames.shape)}")
        b, t = frames.shape[:2]
        size = (self.config.input_size,) * 2
        small = kornia.geometry.transform.resize(frames.flatten(0, 1).float(), size, antialias=True)
        small = small.reshape(b, t, 3, *size)
        diff = torch.cat([torch.zeros_like(small[:, :1]), small[:, 1:] - small[:, :-1]], dim=1)
        x = torch.cat([small - 0.5, diff], dim=2).flatten(0, 1)
        feats = [self.cnn(x[i : i + self.config.chunk]) for i in range(0, x.shape[0], self.config.chunk)]
        return torch.cat(feats).reshape(b, t, -1)

    def forward(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Frames (B, T, 3, H, W) -> positions (B, T, 3) in metres, rotations (B, T, 3, 3) (head-to-world)."""
        h, _ = self.gru(self.frame_features(frames))
        out = self.head(h)
        xz = out[..., 1:3].cumsum(dim=1)
        positions = torch.stack([xz[..., 0], out[..., 0], xz[..., 1]], dim=-1)
        return positions, rotation_6d_to_matrix(out[..., 3:])


def head_trajectory_loss(
    positions: torch.Tensor,
    rotations: torch.Tensor,
    true_positions: torch.Tensor,
    true_rotations: torch.Tensor,
    rotation_weight: float = 1.0,
) -> torch.Tensor:
    """``mean ||p_hat - p||^2 + rotation_weight * mean ||R_hat - R||_F^2``; p (B, T, 3), R (B, T, 3, 3)."""
    pos = (positions - true_positions).pow(2).sum(-1).mean()
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
