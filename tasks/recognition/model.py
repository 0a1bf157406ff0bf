"""The action-recognition network ([EgoMusic] supp. Sec. 8.1, Fig. 10). Pure torch.

N Skeleton Mamba blocks encode every body's clip, global average pooling aggregates time, joints
and bodies, and a linear layer gives the class logits (the softmax is applied by the loss or at
test time)::

    x (B, M, T, J, C) -> fold bodies (B*M, T, J, C) -> SkeletonMamba -> (B*M, T, J, D)
      -> mean over T, J -> (B*M, D) -> mean over the bodies present -> (B, D) -> Linear -> (B, K)

[EgoMusic] supp. Sec. 8.1 writes the pooled embedding as ``o in R^{1x1xC}`` with C the number of classes
before the linear layer; that is the case ``backbone.out_channels = num_classes``. By default the backbone
keeps its width D (``out_channels = None``) and the linear layer maps D to the classes, as the GCN
heads of the reference toolkits do ([PYSKL] ``GCNHead``).
"""

from __future__ import annotations

import torch
from einops import rearrange
from torch import nn

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.pretrained.mixin import PretrainedMixin

__all__ = ["ActionRecognizer", "body_presence", "pool_bodies"]


def body_presence(x: torch.Tensor) -> torch.Tensor:
    """Which bodies carry any non-zero keypoint (zero-padded bodies are absent).

    Args:
        x: (B, M, T, J, C) keypoints.

    Returns:
        (B, M) bool.
    """
    return x.flatten(2).ne(0).any(dim=-1)


def pool_bodies(pooled: torch.Tensor, present: torch.Tensor) -> torch.Tensor:
    """Mean over the bodies present: pooled (B, M, ..., D), present (B, M, ...) -> (B, ..., D).

    A sample with no body present averages every slot.
    """
    present = present | ~present.any(dim=1, keepdim=True)
    weights = present.to(pooled.dtype).unsqueeze(-1)
    return (pooled * weights).sum(dim=1) / weights.sum(dim=1)


class ActionRecognizer(PretrainedMixin, nn.Module):
    """Skeleton Mamba backbone, global average pooling and a linear classifier.

    Args:
        backbone: the backbone configuration (its ``skeleton`` and ``in_channels`` must match the data).
        num_classes: K, the number of action classes.
        dropout: dropout on the pooled embedding before the linear layer.
        input_norm: batch-normalise every joint's channels before the backbone (:meth:`normalize`), as
            PYSKL's GCNs do (``data_bn``): the bone and motion streams (``feats``) are an order of magnitude
            smaller than the joints, and the backbone's linear input layer does not learn from them at
            their raw scale.
    """

    pretrained_task = "Skeleton action recognition: (B, M, T, J, C) keypoints to class logits."
    pretrained_citations = ("EgoMusic", "Mamba-2", "PYSKL")

    def __init__(
        self, backbone: SkeletonMambaConfig, num_classes: int, dropout: float = 0.0, input_norm: bool = False
    ) -> None:
        super().__init__()
        if num_classes < 1:
            raise ValueError(f"num_classes must be positive, got {num_classes}")
        self.backbone = SkeletonMamba(backbone)
        channels = self.backbone.skeleton.num_joints * backbone.in_channels
        self.input_norm = nn.BatchNorm1d(channels) if input_norm else None
        width = backbone.out_channels or backbone.dim
        self.dropout = nn.Dropout(dropout)
        self.head = nn.Linear(width, num_classes)

    def embed(self, x: torch.Tensor) -> torch.Tensor:
        """The pooled embedding.

        Args:
            x: (B, M, T, J, C) keypoints of up to M bodies; absent bodies are all zeros.

        Returns:
            (B, D): the mean over time and joints, then over the bodies present (all bodies when a
            sample has none).
        """
        if x.dim() != 5:
            raise ValueError(f"expected keypoints (B, M, T, J, C), got shape {tuple(x.shape)}")
        b = x.shape[0]
        present = body_presence(x)  # of the keypoints as given (an absent body is zeros)
        features = self.backbone(rearrange(self.normalize(x), "b m t j c -> (b m) t j c"))  # (B*M, T, J, D)
        pooled = rearrange(features.mean(dim=(1, 2)), "(b m) d -> b m d", b=b)
        return pool_bodies(pooled, present)

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` (..., J, C) with every (joint, channel) batch-normalised over the other axes (frames,
        bodies, samples) when ``input_norm``, else as is. In eval mode a per-channel affine map, so a
        frame is normalised alone (the online recognizer's steps)."""
        if self.input_norm is None:
            return x
        return self.input_norm(x.flatten(-2).reshape(-1, x.shape[-2] * x.shape[-1])).reshape(x.shape)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Class logits (B, K) for keypoints (B, M, T, J, C)."""
        return self.head(self.dropout(self.embed(x)))
