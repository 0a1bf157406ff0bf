"""EMM's ONNX graph (``sm export-onnx`` of an ``EMM``; the registration names it).

``denoiser.onnx``: ``x_t`` (batch, frames, 24, 10), ``t`` (batch,) int64, ``context`` (batch, tokens, Dc)
(the fused condition) and ``mask`` (batch, frames) -> ``x0`` (batch, frames, 24, 10); batch, frames and
tokens dynamic (tokens = frames with ``frame_condition``). The condition encoders (music Transformer, the
``transformers`` ResNet of the frames, the fusion) stay in PyTorch: their output is computed once per
clip, the denoiser is what a sampler calls at every step. They do pass strict ``torch.export``, but in
eval mode ``nn.TransformerEncoderLayer`` traces to its fused inference kernel
``aten._transformer_encoder_layer_fwd``, for which ``torch.onnx`` has no ONNX function, so they are not
written as ONNX.
"""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba.tasks.training.onnx_graphs import ExportSpec, network_ready, padding_mask

__all__ = ["emm_specs"]


def emm_specs(emm: nn.Module, batch: int = 2, frames: int = 20) -> dict[str, ExportSpec]:
    """EMM's ``denoiser`` graph: (x_t, t, context, mask) -> x0, the condition already encoded."""
    network_ready(emm)
    per_frame = emm.frame_condition is not None  # one condition token per frame
    tokens = frames if per_frame else frames // 2 + 1
    x_t = torch.randn(batch, frames, *emm.skip_x0.data_mean.shape)
    t = torch.arange(batch, dtype=torch.long) % emm.skip_x0.num_steps
    context = torch.randn(batch, tokens, emm.context_dim)
    axes = {0: "batch", 1: "frames"}
    context_axes = {0: "batch", 1: "frames" if per_frame else "tokens"}
    dynamic = {"x_t": axes, "t": {0: "batch"}, "context": context_axes, "mask": axes}
    spec = ExportSpec(emm, (x_t, t, context, padding_mask(batch, frames)), ["x_t", "t", "context", "mask"],
                      ["x0"], dynamic)  # fmt: skip
    return {"denoiser": spec}
