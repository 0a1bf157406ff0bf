"""The text-to-motion denoiser's ONNX graph (``sm export-onnx`` of a ``TextToMotionDenoiser``; the
registration names it).

``denoiser.onnx``: ``x_t`` (batch, frames, 263), ``t`` (batch,), ``text`` (batch, words, text_dim) caption
token embeddings, ``text_mask`` (batch, words) bool and ``mask`` (batch, frames) -> ``x0`` (batch, frames,
263); the caption encoder stays in PyTorch.
"""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba.tasks.text2motion.model import TextCondition
from skeleton_mamba.tasks.training.onnx_graphs import ExportSpec, network_ready, padding_mask

__all__ = ["TextDenoiserGraph", "text_denoiser_specs"]


class TextDenoiserGraph(nn.Module):
    """The text-to-motion denoiser with its caption condition as two tensors.

    forward(x_t (B, T, 263), t (B,), text (B, S, D), text_mask (B, S), mask (B, T)) -> x0 (B, T, 263).
    """

    def __init__(self, denoiser: nn.Module):
        super().__init__()
        self.denoiser = denoiser

    def forward(
        self,
        x_t: torch.Tensor,
        t: torch.Tensor,
        text: torch.Tensor,
        text_mask: torch.Tensor,
        mask: torch.Tensor,
    ) -> torch.Tensor:
        return self.denoiser(x_t, t, TextCondition(text, text_mask), mask)


def text_denoiser_specs(denoiser: nn.Module, batch: int = 2, frames: int = 20) -> dict[str, ExportSpec]:
    """The text-to-motion denoiser's ``denoiser`` graph: (x_t, t, text, text_mask, mask) -> x0."""
    network_ready(denoiser)
    words = frames // 2 + 1
    x_t = torch.randn(batch, frames, *denoiser.skip_x0.data_mean.shape)
    t = torch.arange(batch, dtype=torch.long) % denoiser.skip_x0.num_steps
    text = torch.randn(batch, words, denoiser.text_proj.in_features)
    text_mask = torch.ones(batch, words, dtype=torch.bool)
    text_mask[-1, words // 2 :] = False
    axes, text_axes = {0: "batch", 1: "frames"}, {0: "batch", 1: "words"}
    spec = ExportSpec(
        TextDenoiserGraph(denoiser), (x_t, t, text, text_mask, padding_mask(batch, frames)),
        ["x_t", "t", "text", "text_mask", "mask"], ["x0"],
        {"x_t": axes, "t": {0: "batch"}, "text": text_axes, "text_mask": text_axes, "mask": axes},
    )  # fmt: skip
    return {"denoiser": spec}
