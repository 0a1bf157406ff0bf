"""The EMM test metrics of one sampling setting: joint errors and MMV ([EgoMusic] supp. 7.1).

BeatAlign, PFC, FID and diversity come from the named dance-evaluation protocol
(:class:`~skeleton_mamba.tasks.motion.metrics.evaluation.DanceEvaluation`), kept beside each group.

:class:`DanceMetrics` is one group of torchmetrics; the test loop keeps one group per head-guidance source
(the estimated head and the oracle head, :class:`.module.EgoDanceModule`) and logs them under
``test/<source>_head/<name>`` at the end of the test epoch.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from torchmetrics import MeanMetric

from skeleton_mamba.tasks.egodance.representation import FPS, HEAD_JOINT
from skeleton_mamba.tasks.motion.metrics.mmv import MMV, visual_beats
from skeleton_mamba.tasks.motion.music.features import BEAT

__all__ = ["DanceMetrics", "video_beats"]


def video_beats(frames: torch.Tensor, fps: float = FPS) -> list[np.ndarray]:
    """The visual beats B_z of MMV for a batch of frames (B, T, 3, H, W) in [0, 1] (motion-frame indices)."""
    videos = (frames.detach().float().clamp(0, 1) * 255).round().to(torch.uint8).permute(0, 1, 3, 4, 2)
    return [visual_beats(v.cpu().numpy(), fps) for v in videos]


class DanceMetrics(nn.Module):
    """MPJPE, root and head joint errors (mm) and MMV (with its MM and MV).

    ``update(pred, true, music, beats)``: joints (B, T, 24, 3) sampled and ground truth, the music
    features (B, T, 35) and the visual beats of each window (:func:`video_beats`; None for music-only
    models: MMV is then not computed).
    """

    def __init__(self, fps: float = FPS):
        super().__init__()
        self.mpjpe, self.root, self.head = MeanMetric(), MeanMetric(), MeanMetric()
        self.mmv = MMV(fps=fps, head_joint=HEAD_JOINT)
        self.has_video = False

    def update(
        self,
        pred: torch.Tensor,
        true: torch.Tensor,
        music: torch.Tensor,
        beats: list[np.ndarray] | None = None,
    ) -> None:
        err = (pred - true).norm(dim=-1) * 1000.0  # (B, T, 24) mm
        self.mpjpe.update(err.mean(dim=(1, 2)))
        self.root.update(err[..., 0].mean(dim=1))
        self.head.update(err[..., HEAD_JOINT].mean(dim=1))
        pred = pred.float().cpu()
        music_beats = music[..., BEAT].cpu()
        if beats is not None:
            self.mmv.update(pred, list(music_beats), video_beats=beats)
            self.has_video = True

    def compute(self) -> dict[str, torch.Tensor]:
        """name -> value (``mmv``, ``mm``, ``mv`` only when videos were given)."""
        out = {
            "mpjpe_mm": self.mpjpe.compute(),
            "root_error_mm": self.root.compute(),
            "head_error_mm": self.head.compute(),
        }
        if self.has_video:
            out.update(self.mmv.compute())
        return {k: torch.as_tensor(v, dtype=torch.float32) for k, v in out.items()}

    def reset(self) -> None:
        for metric in (self.mpjpe, self.root, self.head, self.mmv):
            metric.reset()
        self.has_video = False
