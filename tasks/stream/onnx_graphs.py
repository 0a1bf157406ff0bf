"""The streaming dancer's ONNX graphs (``sm export-onnx`` of a ``StreamDancer``; the registration names them).

``sequence.onnx``: ``prev`` (batch, frames, 24, 12) and ``music`` (batch, frames, M) -> ``pose`` (batch,
frames, 24, 12); ``step.onnx``: ``prev`` (batch, 24, 12), ``music`` (batch, M) and the backbone's state
(:mod:`~skeleton_mamba.tasks.training.onnx_graphs`) -> ``pose`` (batch, 24, 12) and the next state. The music
standardisation is inside the graphs.
"""

from __future__ import annotations

import torch
from torch import nn

from skeleton_mamba.tasks.training.onnx_graphs import (
    ExportSpec,
    StepGraph,
    network_ready,
    state_names,
    zero_states,
)

__all__ = ["DancerStepGraph", "dancer_specs"]


class DancerStepGraph(nn.Module):
    """One frame of the streaming dancer with its state explicit: the dancer's own ``step`` with
    :class:`StepGraph` as its backbone step.

    forward(prev (B, 24, 12), music (B, M), conv_0, ssm_0, ...) -> (pose (B, 24, 12), next_conv_0, ...).
    A dancer with an output low-pass (``dancer.smoothing``) takes two more inputs after ``music``:
    ``started`` (one number: 0 at a stream's first frame, 1 after) and ``smoothing`` (stages, B, 24, 12),
    the low-pass's stages (any value at the first frame), and returns ``next_smoothing`` after ``pose``.
    """

    def __init__(self, dancer: nn.Module):
        super().__init__()
        self.dancer = dancer
        self.backbone_step = StepGraph(dancer.backbone)

    def forward(
        self, prev: torch.Tensor, music: torch.Tensor, *states: torch.Tensor
    ) -> tuple[torch.Tensor, ...]:
        smoothing = self.dancer.smoothing
        if not smoothing.enabled:
            outputs, _ = self.dancer.step(
                prev, music, None, lambda x, _state: (self.backbone_step(x, *states), None)
            )
            return outputs
        started, stages, states = states[0], states[1], states[2:]
        out, *nxt = self.backbone_step(self.dancer._inputs(prev, music), *states)
        pose, stages = smoothing.step(out, stages, started)
        return (pose, stages, *nxt)


def dancer_specs(dancer: nn.Module, batch: int = 2, frames: int = 20) -> dict[str, ExportSpec]:
    """The streaming dancer's ``sequence`` (teacher-forced forward) and ``step`` (one frame) graphs."""
    network_ready(dancer)
    cfg = dancer.backbone.config
    prev = torch.randn(batch, frames, dancer.backbone.skeleton.num_joints, cfg.out_channels)
    music = torch.randn(batch, frames, dancer.music_dim)
    axes = {0: "batch", 1: "frames"}
    sequence = ExportSpec(dancer, (prev, music), ["prev", "music"], ["pose"], {"prev": axes, "music": axes})
    states = [torch.randn_like(t) for t in zero_states(dancer.backbone, batch)]
    names = state_names(len(states))
    inputs, outputs, dynamic = ["prev", "music"], ["pose"], {"prev": {0: "batch"}, "music": {0: "batch"}}
    examples: list[torch.Tensor] = [prev[:, 0], music[:, 0]]
    if dancer.smoothing.enabled:
        examples += [torch.ones(()), torch.randn(dancer.smoothing.stages, *prev[:, 0].shape)]
        inputs, outputs = [*inputs, "started", "smoothing"], [*outputs, "next_smoothing"]
        dynamic["smoothing"] = {1: "batch"}
    step = ExportSpec(
        DancerStepGraph(dancer), (*examples, *states), [*inputs, *names],
        [*outputs, *(f"next_{n}" for n in names)], {**dynamic, **{n: {0: "batch"} for n in names}},
        varargs_from=2,
    )  # fmt: skip
    return {"sequence": sequence, "step": step}
