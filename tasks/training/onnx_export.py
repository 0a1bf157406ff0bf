"""``sm export-onnx``: the backbone or a task network as ONNX graphs (sequence forward, causal step).

Every graph goes through ``torch.export`` (strict) and ``torch.onnx``'s dynamo exporter. A backbone gives
``sequence.onnx`` and, when causal, ``step.onnx`` (:mod:`.onnx_graphs`). A task network (``--ckpt`` /
``--pretrained`` of a task; ``--part backbone`` for its backbone) gives the graphs its task's registration
names (:attr:`~skeleton_mamba.tasks.training.registry.TaskSpec.networks`, built in the task's own folder:
a denoiser graph with the condition already encoded, a sequence forward and a streaming step, ...); a
network no task names exports its backbone. ``export.json`` beside the graphs names the inputs, outputs,
state shapes and the skeleton. Inside an exported graph the SSD runs as one tensor-only form
(``skeleton_mamba.ssd.exportable``, O(frames²) per head), and the padding mask is not value-checked.

Example::

    sm export-onnx --backbone backbones/skeleton_mamba_tiny.yaml --skeleton ntu25 --in-channels 3 \\
        --causal --out onnx/ --check
    sm export-onnx --ckpt runs/stream_dance_demo/version_0/checkpoints/last.ckpt --out onnx/
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import onnxruntime
import torch
from lightning.pytorch import LightningModule
from torch import nn
from torch.export import Dim

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.errors import CheckpointError, InputError
from skeleton_mamba.io.atomic import atomic_path
from skeleton_mamba.pretrained.checks import check_sizes
from skeleton_mamba.pretrained.mixin import PretrainedError, decode_value
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_folder, writing_outputs
from skeleton_mamba.tasks.training.checkpoints import load_checkpoint, load_module_and_checkpoint
from skeleton_mamba.tasks.training.export_onnx_args import build_parser
from skeleton_mamba.tasks.training.onnx_graphs import (
    ExportSpec,
    SequenceGraph,
    StepGraph,
    backbone_specs,
    sequence_spec,
    step_spec,
    zero_states,
)
from skeleton_mamba.tasks.training.pretrained import import_project_class, load_network
from skeleton_mamba.tasks.training.recipe_resolution import (
    packaged_recipe_dir,
    read_yaml_file,
    resolve_backbone,
)
from skeleton_mamba.tasks.training.registry import registered_tasks

__all__ = [
    "ExportSpec",
    "SequenceGraph",
    "StepGraph",
    "backbone_specs",
    "export_onnx",
    "export_program",
    "main",
    "max_difference_from_eager",
    "network_spec_builder",
    "network_specs",
    "run_onnx",
    "sequence_spec",
    "step_spec",
    "zero_states",
]


def network_spec_builder(network: nn.Module) -> Callable[..., dict[str, ExportSpec]] | None:
    """The function building the graphs of ``network`` that a registered task names for its class (matched by
    class name, :attr:`~skeleton_mamba.tasks.training.registry.TaskSpec.networks`), else None."""
    name = type(network).__name__
    for spec in registered_tasks():
        target = spec.networks.get(name)
        if target is not None:
            module, function = target.split(":")
            return getattr(importlib.import_module(module), function)
    return None


def network_specs(network: nn.Module, frames: int = 20) -> dict[str, ExportSpec]:
    """The graphs of a backbone or a task network (:func:`network_spec_builder`); another network: its
    backbone's."""
    if isinstance(network, SkeletonMamba):
        return backbone_specs(network, frames=frames)
    build = network_spec_builder(network)
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
    a registered task names (:func:`network_spec_builder`), else its SkeletonMamba backbone."""
    checkpoint = load_checkpoint(ckpt)
    hparams = checkpoint.get("hyper_parameters") or {}
    class_path = hparams.get("_class_path") if isinstance(hparams, dict) else None
    if not isinstance(class_path, str):
        raise CheckpointError(f"{ckpt}: its hyper-parameters name no module class (_class_path)")
    module, _ = load_module_and_checkpoint(import_project_class(class_path, ckpt, LightningModule), ckpt)
    networks = {name for spec in registered_tasks() for name in spec.networks}
    for m in module.modules():
        if type(m).__name__ in networks or isinstance(m, SkeletonMamba):
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
    produced = [*graphs, "export.json"]
    claim_output_folder(args.out, "sm export-onnx", produced, overwrite=args.overwrite)
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
    with writing_outputs(out, "sm export-onnx", produced, replaces=True):
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
                               "dynamic": spec.dynamic.get(n, {})}
                           for n, a in zip(spec.input_names, spec.args)},
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
