"""LightningModule of the live dance model: teacher-forced next-pose regression ([QEAN] training).

Loss: mean squared error between the predicted and the true joint tokens of every frame, the
previous-pose inputs being the true poses (teacher forcing) plus Gaussian noise of std
``input_noise`` (so the model tolerates its own slightly wrong poses when it runs on them). With
``history_shift`` N > 0 each window's previous poses are also taken ``s`` frames off, ``s`` drawn per window
in ``[-N, N]`` (``pose_{t-1-s}``, the window's edge pose beyond its ends): a history ahead of or behind the
music, as the network's own poses are when it dances live, so the next pose has to be put back on the beat
from the music (the beat phase, :mod:`.beat_phase`) rather than continued from the poses.
Validation reports the same teacher-forced loss. Inference is ``sm stream`` (:mod:`.stream_cli`).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.stream.features import NUM_FEATURES
from skeleton_mamba.tasks.stream.model import StreamDancer, teacher_forcing_inputs
from skeleton_mamba.tasks.training.base_module import BackboneModule

__all__ = ["StreamDanceModule"]


class StreamDanceModule(BackboneModule):
    """Causal music-to-dance on Skeleton Mamba.

    Args:
        backbone: backbone size (``backbones/skeleton_mamba.yaml``); made causal by the model.
        music_dim: music features per frame (34, :mod:`.features`).
        input_noise: std of the noise added to the teacher-forced previous poses.
        history_shift: the largest shift (frames) of a window's teacher-forced previous poses (0: none).
        smoothing_stages: moving averages of the network's causal output low-pass, trained through
            (:mod:`~skeleton_mamba.tasks.training.causal_smoothing`; 0: none).
        smoothing_decay: their decay.
        lr: AdamW learning rate.
        weight_decay: AdamW weight decay.
    """

    def __init__(
        self,
        backbone: SkeletonMambaConfig | None = None,
        music_dim: int = NUM_FEATURES,
        input_noise: float = 0.02,
        history_shift: int = 0,
        smoothing_stages: int = 0,
        smoothing_decay: float = 0.6,
        lr: float = 3e-4,
        weight_decay: float = 0.01,
    ) -> None:
        super().__init__()
        if history_shift < 0:
            raise ValueError(f"history_shift must be >= 0 frames, got {history_shift}")
        config = self.save_backbone_hyperparameters(backbone)
        self.model = StreamDancer(config, music_dim, smoothing_stages, smoothing_decay)

    def set_data_statistics(self, statistics) -> None:
        """The music normalisation from every training music frame (``music`` (N, 34),
        :class:`.data.StreamStatistics`)."""
        self.model.set_music_statistics(statistics.music.to(self.device))

    def _shifted_history(self, motion: torch.Tensor) -> torch.Tensor:
        """Previous poses (B, T, 24, 12) taken ``s`` frames off per window, ``s`` in [-N, N] (module doc)."""
        n = self.hparams.history_shift
        steps = torch.arange(motion.shape[1], device=motion.device)
        shifts = torch.randint(-n, n + 1, (motion.shape[0], 1), device=motion.device)
        index = (steps[None] - 1 - shifts).clamp(0, motion.shape[1] - 1)  # (B, T)
        prev = motion.gather(1, index[..., None, None].expand_as(motion))
        prev[:, 0] = torch.where((shifts[:, 0] >= 0)[:, None, None], 0.0, prev[:, 0])  # the start token
        return prev

    def _loss(self, batch: dict[str, torch.Tensor], noise: float) -> torch.Tensor:
        motion = batch["motion"]
        shifted = self.training and self.hparams.history_shift > 0
        prev = self._shifted_history(motion) if shifted else teacher_forcing_inputs(motion)
        if noise > 0:
            prev = prev + noise * torch.randn_like(prev)
        return F.mse_loss(self.model(prev, batch["music"]), motion)

    def training_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> torch.Tensor:
        loss = self._loss(batch, self.hparams.input_noise)
        self.log("train/loss", loss, prog_bar=True, batch_size=batch["motion"].shape[0])
        return loss

    def validation_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        loss = self._loss(batch, 0.0)
        self.log("val/loss", loss, prog_bar=True, batch_size=batch["motion"].shape[0])

    def configure_optimizers(self):
        return torch.optim.AdamW(
            self.parameters(), lr=self.hparams.lr, weight_decay=self.hparams.weight_decay
        )
