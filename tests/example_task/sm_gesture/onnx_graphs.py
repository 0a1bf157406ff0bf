"""The gesture network's ONNX graph: ``sequence.onnx`` ``x`` (batch, frames, J, 2) -> ``logits``."""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba.tasks.training.onnx_graphs import ExportSpec, network_ready


def gesture_specs(network: nn.Module, batch: int = 2, frames: int = 20) -> dict[str, ExportSpec]:
    """The ``sequence`` graph of a :class:`~sm_gesture.model.GestureClassifier`, batch and frames dynamic."""
    network_ready(network)
    x = torch.randn(batch, frames, network.backbone.skeleton.num_joints, 2)
    axes = {0: "batch", 1: "frames"}
    return {"sequence": ExportSpec(network, (x,), ["x"], ["logits"], {"x": axes})}
