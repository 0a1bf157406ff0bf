"""The ONNX graphs' building blocks: what to export (:class:`ExportSpec`) and the backbone's graphs.

Graphs of the backbone:

- ``sequence.onnx``: ``x`` (batch, frames, J, C_in) float32 and ``mask`` (batch, frames) bool (True on
  valid frames, a valid prefix per row) -> ``y`` (batch, frames, J, D or C_out); batch and frames dynamic.
- ``step.onnx`` (causal backbones): one frame ``x`` (batch, J, C_in) and the recurrent state as explicit
  tensors, per block i ``conv_i`` (batch, J, conv_dim, d_conv) and ``ssm_i`` (batch, J, nheads,
  headdim, d_state), -> ``y`` (batch, J, D or C_out) and the next state ``next_conv_i`` / ``next_ssm_i``;
  batch dynamic. Zeros are the state of a new stream; feeding each step's next state to the following
  step equals the causal sequence forward ([Mamba-2] SSD recurrence, ``skeleton_mamba.runtime.streaming``).

A task's networks build their graphs from these pieces in the task's own folder (its ``onnx_graphs.py``,
named by its registration's :attr:`~skeleton_mamba.tasks.training.registry.TaskSpec.networks`);
:mod:`.onnx_export` (``sm export-onnx``) writes and checks them. Pure torch: no ONNX package is imported here.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import torch
from torch import nn

from skeleton_mamba import SkeletonMamba
from skeleton_mamba.errors import InputError
from skeleton_mamba.runtime.streaming import frame_forward

__all__ = [
    "ExportSpec",
    "SequenceGraph",
    "StepGraph",
    "backbone_specs",
    "export_ready",
    "network_ready",
    "padding_mask",
    "sequence_spec",
    "state_names",
    "step_spec",
    "zero_states",
]


@dataclass
class ExportSpec:
    """A module to export with example inputs, the graph's names and its dynamic axes.

    Attributes:
        module: takes ``args`` positionally and returns a tensor or a tuple of tensors.
        args: example inputs, in the order of ``input_names``.
        input_names, output_names: the names in the ONNX graph.
        dynamic: input name -> {axis: dimension name}; inputs sharing a name share the dimension.
        varargs_from: the position from which ``module.forward`` takes its inputs as ``*args``, if it does.
    """

    module: nn.Module
    args: tuple[torch.Tensor, ...]
    input_names: list[str]
    output_names: list[str]
    dynamic: dict[str, dict[int, str]] = field(default_factory=dict)
    varargs_from: int | None = None


class SequenceGraph(nn.Module):
    """``backbone(x, mask)``, the mask a positional input: (B, T, J, C), (B, T) -> (B, T, J, D)."""

    def __init__(self, backbone: SkeletonMamba):
        super().__init__()
        self.backbone = backbone

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return self.backbone(x, mask)


class StepGraph(nn.Module):
    """One frame of a causal backbone with its state as explicit inputs and outputs (no in-place update).

    forward(x (B, J, C), conv_0, ssm_0, conv_1, ssm_1, ...) -> (y (B, J, D), next_conv_0, next_ssm_0, ...)
    with conv_i (B, J, conv_dim, d_conv) and ssm_i (B, J, nheads, headdim, d_state): the
    :class:`~skeleton_mamba.runtime.streaming.StreamState` tensors of block i with the streams' rows (B·J)
    split into (B, J), so every input has the batch first.
    """

    def __init__(self, backbone: SkeletonMamba):
        super().__init__()
        if not backbone.config.causal:
            raise InputError("the streaming step needs a causal backbone (SkeletonMambaConfig(causal=True))")
        self.backbone = backbone

    def forward(self, x: torch.Tensor, *states: torch.Tensor) -> tuple[torch.Tensor, ...]:
        b, j = x.shape[:2]
        conv = [s.reshape(b * j, *s.shape[2:]).clone() for s in states[0::2]]
        ssm = [s.reshape(b * j, *s.shape[2:]).clone() for s in states[1::2]]
        y = frame_forward(self.backbone, x, conv, ssm)  # updates the clones in place
        nxt = [t for pair in zip(conv, ssm) for t in pair]
        return (y, *(t.reshape(b, j, *t.shape[1:]) for t in nxt))


def export_ready(backbone: SkeletonMamba) -> SkeletonMamba:
    """The backbone in eval mode, with no CPU slicing (one call over everything; exact, see its config)."""
    backbone.eval()
    backbone.config = replace(backbone.config, cpu_slice_elements=None)
    for block in backbone.blocks:
        block.slice_elements = None
        block.temporal_scan.slice_elements = None
    return backbone


def sequence_spec(backbone: SkeletonMamba, batch: int = 2, frames: int = 20) -> ExportSpec:
    """The sequence forward with example inputs (one padded sequence), batch and frames dynamic."""
    if backbone.config.context_dim is not None:
        raise InputError(
            "a backbone with cross-attention (context_dim) exports inside its task network's denoiser graph"
        )
    j = backbone.skeleton.num_joints
    c = backbone.config.in_channels or backbone.config.dim
    x = torch.randn(batch, frames, j, c)
    mask = padding_mask(batch, frames)
    axes = {0: "batch", 1: "frames"}
    return ExportSpec(SequenceGraph(export_ready(backbone)), (x, mask), ["x", "mask"], ["y"],
                      {"x": axes, "mask": axes})  # fmt: skip


def zero_states(backbone: SkeletonMamba, batch: int) -> list[torch.Tensor]:
    """The zero state of :class:`StepGraph` for ``batch`` streams: conv_0, ssm_0, conv_1, ..."""
    state = backbone.init_state(batch)
    j = backbone.skeleton.num_joints
    return [t.reshape(batch, j, *t.shape[1:]) for pair in zip(state.conv, state.ssm) for t in pair]


def step_spec(backbone: SkeletonMamba, batch: int = 2) -> ExportSpec:
    """The causal step with example inputs (a frame and random states), batch dynamic."""
    graph = StepGraph(export_ready(backbone))
    j = backbone.skeleton.num_joints
    c = backbone.config.in_channels or backbone.config.dim
    states = [torch.randn_like(t) for t in zero_states(backbone, batch)]
    names = state_names(len(states))
    dynamic = {name: {0: "batch"} for name in ["x", *names]}
    return ExportSpec(graph, (torch.randn(batch, j, c), *states), ["x", *names],
                      ["y", *(f"next_{n}" for n in names)], dynamic, varargs_from=1)  # fmt: skip


def padding_mask(batch: int, frames: int) -> torch.Tensor:
    """(batch, frames) bool, all valid but the last row's second half (a padded sequence)."""
    mask = torch.ones(batch, frames, dtype=torch.bool)
    mask[-1, frames // 2 :] = False
    return mask


def network_ready(network: nn.Module) -> nn.Module:
    """The network in eval mode with every backbone in it :func:`export_ready`."""
    for module in network.modules():
        if isinstance(module, SkeletonMamba):
            export_ready(module)
    return network.eval()


def state_names(count: int) -> list[str]:
    """The state inputs' names of :class:`StepGraph`: ``conv_0``, ``ssm_0``, ``conv_1``, ..."""
    return [f"{kind}_{i}" for i in range(count // 2) for kind in ("conv", "ssm")]


def backbone_specs(backbone: SkeletonMamba, batch: int = 2, frames: int = 20) -> dict[str, ExportSpec]:
    """The backbone's graphs: ``sequence`` and, for a causal backbone, ``step``."""
    specs = {"sequence": sequence_spec(backbone, batch, frames)}
    if backbone.config.causal:
        specs["step"] = step_spec(backbone, batch)
    return specs
