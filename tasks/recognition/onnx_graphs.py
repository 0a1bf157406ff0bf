"""The recognition network's ONNX graph (``sm export-onnx`` of an ``ActionRecognizer``; the registration
names it).

``sequence.onnx``: ``x`` (batch, bodies, frames, J, C) -> ``logits`` (batch, classes); batch and frames
dynamic (absent bodies are zeros, as in PyTorch).
"""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba.tasks.training.onnx_graphs import ExportSpec, network_ready

__all__ = ["recognizer_specs"]


def recognizer_specs(
    network: nn.Module, batch: int = 2, frames: int = 20, bodies: int = 2
) -> dict[str, ExportSpec]:
    """The recognition network's ``sequence`` graph: keypoints (B, M, T, J, C) -> logits (B, K).

    The example's last sample has its other bodies absent (zeros), the padding the network reads.
    """
    network_ready(network)
    cfg = network.backbone.config
    x = torch.randn(batch, bodies, frames, network.backbone.skeleton.num_joints, cfg.in_channels or cfg.dim)
    x[-1, 1:] = 0.0
    axes = {0: "batch", 1: "bodies", 2: "frames"}
    return {"sequence": ExportSpec(network, (x,), ["x"], ["logits"], {"x": axes})}
