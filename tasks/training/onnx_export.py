"""``sm export-onnx``: the backbone or a task network as ONNX graphs (sequence forward, causal step).

Every graph goes through ``torch.export`` (strict) and ``torch.onnx``'s dynamo exporter. Graphs of the
backbone:

- ``sequence.onnx``: ``x`` (batch, frames, J, C_in) float32 and ``mask`` (batch, frames) bool (True on
  valid frames, a valid prefix per row) -> ``y`` (batch, frames, J, D or C_out); batch and frames dynamic.
- ``step.onnx`` (causal backbones): one frame ``x`` (batch, J, C_in) and the recurrent state as explicit
  tensors, per block i ``conv_i`` (batch, J, conv_dim, d_conv) and ``ssm_i`` (batch, J, nheads,
  headdim, d_state), -> ``y`` (batch, J, D or C_out) and the next state ``next_conv_i`` / ``next_ssm_i``;
  batch dynamic. Zeros are the state of a new stream; feeding each step's next state to the following
  step equals the causal sequence forward ([Mamba-2] SSD recurrence, ``skeleton_mamba.streaming``).

Graphs of the task networks (``--ckpt`` / ``--pretrained`` of a task; ``--part backbone`` for its backbone):

- streaming dancer (``StreamDancer``): ``sequence.onnx`` ``prev`` (batch, frames, 24, 12) and ``music``
  (batch, frames, M) -> ``pose`` (batch, frames, 24, 12); ``step.onnx`` ``prev`` (batch, 24, 12), ``music``
  (batch, M) and the state as above -> ``pose`` (batch, 24, 12) and the next state. The music
  standardisation is inside the graphs.
- recognition network (``ActionRecognizer``): ``sequence.onnx`` ``x`` (batch, bodies, frames, J, C) ->
  ``logits`` (batch, classes); batch and frames dynamic (absent bodies are zeros, as in PyTorch).
- EMM (``EMM``): ``denoiser.onnx`` ``x_t`` (batch, frames, 24, 10), ``t`` (batch,) int64, ``context``
  (batch, tokens, Dc) (the fused condition) and ``mask`` (batch, frames) -> ``x0`` (batch, frames, 24,
  10); batch, frames and tokens dynamic (tokens = frames with ``frame_condition``). The condition
  encoders (music Transformer, the ``transformers`` ResNet of the frames, the fusion) stay in
  PyTorch: their output is computed once per clip, the denoiser is what a sampler calls at every step.
  They do pass strict ``torch.export``, but in eval mode ``nn.TransformerEncoderLayer`` traces to its
  fused inference kernel ``aten._transformer_encoder_layer_fwd``, for which ``torch.onnx`` has no ONNX
  function, so they are not written as ONNX.
- text-to-motion denoiser (``TextToMotionDenoiser``): ``denoiser.onnx`` ``x_t`` (batch, frames, 263),
  ``t`` (batch,), ``text`` (batch, words, text_dim) caption token embeddings, ``text_mask`` (batch, words)
  bool and ``mask`` (batch, frames) -> ``x0`` (batch, frames, 263); the caption encoder stays in PyTorch.

Other networks (QEAN) export their backbone. ``export.json`` beside the graphs names the inputs,
outputs, state shapes and the skeleton. Inside an exported graph the SSD runs as one tensor-only form
(``skeleton_mamba.ssd.exportable``, O(frames²) per head), and the padding mask is not value-checked.

Example::

    sm export-onnx --backbone backbones/skeleton_mamba_tiny.yaml --skeleton ntu25 --in-channels 3 \\
        --causal --out onnx/ --check
    sm export-onnx --ckpt runs/stream_dance_demo/version_0/checkpoints/last.ckpt --out onnx/
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import onnxruntime
import torch
from lightning.pytorch import LightningModule
from torch import nn
from torch.export import Dim

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.pretrained import PretrainedError, decode_value
from skeleton_mamba.pretrained_checks import check_sizes
from skeleton_mamba.streaming import frame_forward
from skeleton_mamba.tasks.motion.atomic import atomic_path
from skeleton_mamba.tasks.motion.errors import CheckpointError, InputError
from skeleton_mamba.tasks.motion.output_folder import claim_output_folder
from skeleton_mamba.tasks.training.checkpoints import load_checkpoint, load_module_and_checkpoint
from skeleton_mamba.tasks.training.onnx_export_args import build_parser
from skeleton_mamba.tasks.training.pretrained import import_project_class, load_network
from skeleton_mamba.tasks.training.recipe_resolution import (
    packaged_recipe_dir,
    read_yaml_file,
    resolve_backbone,
)

__all__ = [
    "NETWORK_SPECS",
    "DancerStepGraph",
    "ExportSpec",
    "SequenceGraph",
    "StepGraph",
    "TextDenoiserGraph",
    "TextTokens",
    "backbone_specs",
    "dancer_specs",
    "emm_specs",
    "export_onnx",
    "export_program",
    "main",
    "max_difference_from_eager",
    "network_ready",
    "network_specs",
    "recognizer_specs",
    "run_onnx",
    "sequence_spec",
    "state_names",
    "step_spec",
    "text_denoiser_specs",
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
    :class:`~skeleton_mamba.streaming.StreamState` tensors of block i with the streams' rows (B·J)
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


@dataclass
class TextTokens:
    """A caption condition as the text-to-motion denoiser reads it: ``tokens`` (B, S, D), ``mask`` (B, S)."""

    tokens: torch.Tensor
    mask: torch.Tensor


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
        return self.denoiser(x_t, t, TextTokens(text, text_mask), mask)


def _export_ready(backbone: SkeletonMamba) -> SkeletonMamba:
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
    mask = _padding_mask(batch, frames)
    axes = {0: "batch", 1: "frames"}
    return ExportSpec(SequenceGraph(_export_ready(backbone)), (x, mask), ["x", "mask"], ["y"],
                      {"x": axes, "mask": axes})  # fmt: skip


def zero_states(backbone: SkeletonMamba, batch: int) -> list[torch.Tensor]:
    """The zero state of :class:`StepGraph` for ``batch`` streams: conv_0, ssm_0, conv_1, ..."""
    state = backbone.init_state(batch)
    j = backbone.skeleton.num_joints
    return [t.reshape(batch, j, *t.shape[1:]) for pair in zip(state.conv, state.ssm) for t in pair]


def step_spec(backbone: SkeletonMamba, batch: int = 2) -> ExportSpec:
    """The causal step with example inputs (a frame and random states), batch dynamic."""
    graph = StepGraph(_export_ready(backbone))
    j = backbone.skeleton.num_joints
    c = backbone.config.in_channels or backbone.config.dim
    states = [torch.randn_like(t) for t in zero_states(backbone, batch)]
    names = state_names(len(states))
    dynamic = {name: {0: "batch"} for name in ["x", *names]}
    return ExportSpec(graph, (torch.randn(batch, j, c), *states), ["x", *names],
                      ["y", *(f"next_{n}" for n in names)], dynamic, varargs_from=1)  # fmt: skip


def _padding_mask(batch: int, frames: int) -> torch.Tensor:
    """(batch, frames) bool, all valid but the last row's second half (a padded sequence)."""
    mask = torch.ones(batch, frames, dtype=torch.bool)
    mask[-1, frames // 2 :] = False
    return mask


def network_ready(network: nn.Module) -> nn.Module:
    """The network in eval mode with every backbone in it :func:`_export_ready`."""
    for module in network.modules():
        if isinstance(module, SkeletonMamba):
            _export_ready(module)
    return network.eval()


def state_names(count: int) -> list[str]:
    """The names of ``count`` step-graph state tensors: ``conv_0, ssm_0, conv_1, ssm_1, ...``."""
    return [f"{kind}_{i}" for i in range(count // 2) for kind in ("conv", "ssm")]


def backbone_specs(backbone: SkeletonMamba, batch: int = 2, frames: int = 20) -> dict[str, ExportSpec]:
    """The backbone's graphs: ``sequence`` and, for a causal backbone, ``step``."""
    specs = {"sequence": sequence_spec(backbone, batch, frames)}
    if backbone.config.causal:
        specs["step"] = step_spec(backbone, batch)
    return specs


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
    spec = ExportSpec(emm, (x_t, t, context, _padding_mask(batch, frames)), ["x_t", "t", "context", "mask"],
                      ["x0"], dynamic)  # fmt: skip
    return {"denoiser": spec}


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
        TextDenoiserGraph(denoiser), (x_t, t, text, text_mask, _padding_mask(batch, frames)),
        ["x_t", "t", "text", "text_mask", "mask"], ["x0"],
        {"x_t": axes, "t": {0: "batch"}, "text": text_axes, "text_mask": text_axes, "mask": axes},
    )  # fmt: skip
    return {"denoiser": spec}


NETWORK_SPECS = {
    "StreamDancer": dancer_specs,
    "ActionRecognizer": recognizer_specs,
    "EMM": emm_specs,
    "TextToMotionDenoiser": text_denoiser_specs,
}
"""Task network class name -> its graphs (matched by name: this layer imports no task)."""


def network_specs(network: nn.Module, frames: int = 20) -> dict[str, ExportSpec]:
    """The graphs of a backbone or a task network (:data:`NETWORK_SPECS`); another network: its backbone's."""
    if isinstance(network, SkeletonMamba):
        return backbone_specs(network, frames=frames)
    build = NETWORK_SPECS.get(type(network).__name__)
    if build is not None:
        return build(network, frames=frames)
    return backbone_specs(backbone_of(network, f"a {type(network).__name__}"), frames=frames)


def export_program(spec: ExportSpec, strict: bool = True) -> torch.export.ExportedProgram:
    """``torch.export.export`` of ``spec`` with its dynamic axes (strict: traced by TorchDynamo)."""
    dims: dict[str, Dim] = {}
    shapes = []
    for name in spec.input_names:
        axes = spec.dynamic.get(name, {})
        shapes.append({axis: dims.setdefault(dim, Dim(dim)) for axis, dim in axes.items()} or None)
    if spec.varargs_from is not None:
        shapes = [*shapes[: spec.varargs_from], tuple(shapes[spec.varargs_from :])]
    with torch.no_grad():
        return torch.export.export(spec.module, spec.args, dynamic_shapes=tuple(shapes), strict=strict)


def export_onnx(
    spec: ExportSpec, path: str | Path, program: torch.export.ExportedProgram | None = None
) -> Path:
    """Write ``spec`` (or its exported ``program``) as an ONNX file at ``path`` (written atomically)."""
    program = export_program(spec) if program is None else program
    path = Path(path)
    onnx_program = torch.onnx.export(
        program, spec.args, input_names=spec.input_names, output_names=spec.output_names, dynamo=True,
        verbose=False, optimize=True,
    )  # fmt: skip
    with atomic_path(path) as tmp:
        onnx_program.save(str(tmp))
    return path


def run_onnx(path: str | Path, inputs: dict[str, torch.Tensor]) -> list[np.ndarray]:
    """Run an ONNX file with onnxruntime on the CPU; returns its outputs in graph order."""
    session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    names = {i.name for i in session.get_inputs()}
    return session.run(None, {k: v.numpy() for k, v in inputs.items() if k in names})


def max_difference_from_eager(spec: ExportSpec, path: Path) -> float:
    """Max abs difference between onnxruntime and eager PyTorch on the example inputs."""
    with torch.no_grad():
        eager = spec.module(*spec.args)
    eager = eager if isinstance(eager, tuple) else (eager,)
    ours = run_onnx(path, dict(zip(spec.input_names, spec.args)))
    return max(float(np.abs(o - e.numpy()).max()) for o, e in zip(ours, eager))


def network_from_checkpoint(ckpt: str) -> nn.Module:
    """The network of a Lightning checkpoint (read through the one checker): the first module in it that
    :data:`NETWORK_SPECS` names, else its SkeletonMamba backbone."""
    checkpoint = load_checkpoint(ckpt)
    hparams = checkpoint.get("hyper_parameters") or {}
    class_path = hparams.get("_class_path") if isinstance(hparams, dict) else None
    if not isinstance(class_path, str):
        raise CheckpointError(f"{ckpt}: its hyper-parameters name no module class (_class_path)")
    module, _ = load_module_and_checkpoint(import_project_class(class_path, ckpt, LightningModule), ckpt)
    for m in module.modules():
        if type(m).__name__ in NETWORK_SPECS or isinstance(m, SkeletonMamba):
            return m
    raise CheckpointError(f"{ckpt}: its module holds no SkeletonMamba backbone")


def backbone_from_checkpoint(ckpt: str) -> SkeletonMamba:
    """The SkeletonMamba inside the network of a Lightning checkpoint (read through the one checker)."""
    return backbone_of(network_from_checkpoint(ckpt), ckpt)


def backbone_of(network: nn.Module, source: str) -> SkeletonMamba:
    """The (first) SkeletonMamba in ``network``."""
    backbones = [m for m in network.modules() if isinstance(m, SkeletonMamba)]
    if not backbones:
        raise CheckpointError(f"{source}: its network holds no SkeletonMamba backbone")
    return backbones[0]


def backbone_from_yaml(path: str, overrides: dict) -> SkeletonMamba:
    """A fresh SkeletonMamba from a backbone YAML file and overrides: a path, or a packaged fragment as a
    recipe names it (``backbones/skeleton_mamba_tiny.yaml``, or ``skeleton_mamba_tiny``).

    The file is read by the bounded YAML reader; its fields are decoded with the types of
    :class:`SkeletonMambaConfig` (an unknown field, a list where a number belongs, a mixer that is not a
    mapping are refused naming the field) and its sizes checked against their bounds before anything is
    built.

    Raises:
        InputError: naming the file and what is wrong.
    """
    p = resolve_backbone(path)
    if p is None:
        names = sorted(f.stem for f in (packaged_recipe_dir() / "backbones").glob("*.yaml"))
        raise InputError(f"{path}: no such backbone file, nor a packaged one (packaged: {', '.join(names)})")
    path = str(p)
    fields = read_yaml_file(p, "backbone file")
    fields = {} if fields is None else fields
    if not isinstance(fields, dict):
        raise InputError(f"{path}: a backbone file holds a mapping of SkeletonMambaConfig fields")
    merged = {**fields, **{k: v for k, v in overrides.items() if v is not None}}
    try:
        config = decode_value(merged, SkeletonMambaConfig, f"{path}: SkeletonMambaConfig")
    except PretrainedError as err:
        raise InputError(str(err)) from err
    check_sizes(config, f"{path}: SkeletonMambaConfig", InputError)
    try:
        return SkeletonMamba(config)
    except (TypeError, ValueError, KeyError, RuntimeError) as err:
        raise InputError(f"{path}: not a usable backbone ({err})") from err


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm export-onnx``; returns the exit code."""
    args = build_parser().parse_args(list(argv) if argv is not None else None)
    graphs = [f"{g}.onnx{data}" for g in ("sequence", "step", "denoiser") for data in ("", ".data")]
    claim_output_folder(args.out, "sm export-onnx", [*graphs, "export.json"], overwrite=args.overwrite,
                        marker=lambda folder: (folder / "export.json").is_file())  # fmt: skip
    if args.ckpt is not None:
        network, source = network_from_checkpoint(args.ckpt), args.ckpt
    elif args.pretrained is not None:
        network, source = load_network(args.pretrained), args.pretrained
    else:
        overrides = {"skeleton": args.skeleton, "in_channels": args.in_channels, "causal": args.causal}
        network, source = backbone_from_yaml(args.backbone, overrides), args.backbone
    if args.part == "backbone":
        network = backbone_of(network, source)
    out = Path(args.out)
    specs = network_specs(network, frames=args.frames)
    backbone = backbone_of(network, source)
    record = {
        "network": type(network).__name__,
        "skeleton": backbone.skeleton.name,
        "num_joints": backbone.skeleton.num_joints,
        "graphs": {},
    }
    for name, spec in specs.items():
        print(f"sm export-onnx: exporting {name} ...", flush=True)
        path = export_onnx(spec, out / f"{name}.onnx")
        entry = {
            "file": path.name,
            "inputs": {n: {"shape": list(a.shape), "dtype": str(a.dtype).removeprefix("torch."),
                           "dynamic": spec.dynamic.get(n, {})} for n, a in zip(spec.input_names, spec.args)},
            "outputs": spec.output_names,
        }  # fmt: skip
        if args.check:
            diff = entry["max_abs_diff_vs_eager"] = max_difference_from_eager(spec, path)
            print(f"sm export-onnx: {name}: onnxruntime vs eager max |diff| {diff:.2e}")
        record["graphs"][name] = entry
    with atomic_path(out / "export.json") as tmp:
        tmp.write_text(json.dumps(record, indent=2) + "\n")
    print(f"sm export-onnx: wrote {', '.join(f'{n}.onnx' for n in specs)} and export.json to {out}")
    return 0
