"""The gesture LightningModule: cross-entropy and Adam on :class:`~sm_gesture.model.GestureClassifier`."""

from __future__ import annotations

import dataclasses

import torch
import torch.nn.functional as F

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.training.base_module import BackboneModule
from sm_gesture.model import GestureClassifier


class GestureModule(BackboneModule):
    """Gesture classifier.

    Args:
        backbone: the backbone configuration (its ``skeleton`` and ``in_channels`` are the data's).
        num_classes: gesture classes, linked from the data module.
        skeleton: skeleton name, linked from the data module.
        lr: Adam's learning rate.
    """

    def __init__(
        self,
        backbone: SkeletonMambaConfig | None = None,
        num_classes: int = 4,
        skeleton: str = "openpose18",
        lr: float = 1e-3,
    ) -> None:
        super().__init__()
        config = self.save_backbone_hyperparameters(backbone)
        config = dataclasses.replace(config, skeleton=skeleton, in_channels=2)
        self.model = GestureClassifier(config, num_classes)

    def _loss(self, batch: tuple[torch.Tensor, torch.Tensor], split: str) -> torch.Tensor:
        keypoints, label = batch
        loss = F.cross_entropy(self.model(keypoints), label)
        self.log(f"{split}/loss", loss, prog_bar=split == "train")
        return loss

    def training_step(self, batch: tuple[torch.Tensor, torch.Tensor], batch_idx: int) -> torch.Tensor:
        return self._loss(batch, "train")

    def validation_step(self, batch: tuple[torch.Tensor, torch.Tensor], batch_idx: int) -> None:
        self._loss(batch, "val")

    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.Adam(self.parameters(), lr=self.hparams.lr)
