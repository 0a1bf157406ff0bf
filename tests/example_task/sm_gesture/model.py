"""The gesture network: a Skeleton Mamba backbone, mean pooling and a linear layer (pure torch)."""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.pretrained.mixin import PretrainedMixin


class GestureClassifier(PretrainedMixin, nn.Module):
    """(B, T, J, C) keypoints -> (B, num_classes) logits."""

    pretrained_task = "Gesture classes from 2-D keypoints (example task)."

    def __init__(self, backbone: SkeletonMambaConfig, num_classes: int):
        super().__init__()
        self.backbone = SkeletonMamba(backbone)
        self.head = nn.Linear(backbone.dim, num_classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.backbone(x).mean(dim=(1, 2)))
