"""LightningModule of the live dance model: teacher-forced next-pose regression ([QEAN] training).

Loss: mean squared error between the predicted and the true joint tokens of every frame, the
previous-pose inputs being the true poses (teacher forcing) plus Gaussian noise of std
``input_noise`` (so the model tolerates its own slightly wrong poses when it runs on them).
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
        smoothing_stages: int = 0,
        smoothing_decay: float = 0.6,
        lr: float = 3e-4,
        weight_decay: float = 0.01,
    ) -> None:
        super().__init__()
        config = self.save_backbone_hyperparameters(backbone)
        self.model = StreamDancer(config, music_dim, smoothing_stages, smoothing_decay)

    def set_data_statistics(self, statistics) -> None:
        """The music normalisation from every training music frame (``music`` (N, 34),
        :class:`.data.StreamStatistics`)."""
        self.model.set_music_statistics(statistics.music.to(self.device))

    def _loss(self, batch: dict[str, torch.Tensor], noise: float) -> torch.Tensor:
        motion = batch["motion"]
        prev = teacher_forcing_inputs(motion)
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
