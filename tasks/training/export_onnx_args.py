"""The command line of ``sm export-onnx`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.pretrained.size_bounds import SIZE_BOUNDS
from skeleton_mamba.tasks.motion.commands.cli_options import command_parser
from skeleton_mamba.tasks.motion.io.option_types import int_option
from skeleton_mamba.tasks.motion.io.output_folder import OVERWRITE_HELP

__all__ = ["MAX_EXAMPLE_FRAMES", "PART_HELP", "build_parser"]

MAX_EXAMPLE_FRAMES = 4096  # frames of the example input: the graphs' SSD is quadratic in the frames

PART_HELP = (
    "network (default): a task network's own graphs (the streaming dancer: sequence and step; the "
    "recognition network: sequence; EMM and the text-to-motion denoiser: denoiser, the condition or caption "
    "already encoded (the caption encoder is not part of the network; EMM's condition encoders stay in "
    "PyTorch: nn.TransformerEncoderLayer's fused inference op aten._transformer_encoder_layer_fwd has no "
    "ONNX function); other networks (QEAN): their backbone's); backbone: its SkeletonMamba only"
)

EXAMPLES = """examples:
  sm export-onnx --backbone backbones/skeleton_mamba_tiny.yaml --skeleton ntu25 --in-channels 3 \\
      --causal --out onnx/ --check
  sm export-onnx --ckpt runs/stream_dance_demo/version_0/checkpoints/last.ckpt --out onnx/"""


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm export-onnx",
        "Export the backbone or a task network as ONNX graphs: the sequence forward and, for a causal "
        "network, the streaming step with its state as explicit tensors; export.json names the inputs, "
        "outputs and state shapes.",
        EXAMPLES,
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--ckpt", help="a Lightning checkpoint: its task network (see --part) is exported")
    src.add_argument("--pretrained", help="a from_pretrained folder or Hub id (a backbone or a task network)")
    src.add_argument(
        "--backbone",
        help="a backbone YAML (fresh weights): a path, or a packaged one as recipes name it "
        "(backbones/skeleton_mamba_tiny.yaml, or skeleton_mamba_tiny)",
    )
    p.add_argument("--part", choices=("network", "backbone"), default="network", help=PART_HELP)
    p.add_argument("--skeleton", default=None, help="with --backbone: the skeleton")
    p.add_argument(
        "--in-channels",
        type=int_option(1, SIZE_BOUNDS["in_channels"], "a channel count"),
        default=None,
        help="with --backbone: input features per joint",
    )
    p.add_argument("--causal", action="store_true", default=None, help="with --backbone: a causal backbone")
    p.add_argument(
        "--out",
        required=True,
        help="the folder to write (created; an existing one must be an earlier export)",
    )
    p.add_argument(
        "--frames",
        type=int_option(2, MAX_EXAMPLE_FRAMES, "a frame count"),
        default=20,
        help="frames of the example input; the graphs take any length",
    )
    p.add_argument("--check", action="store_true", help="compare onnxruntime with eager PyTorch")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    return p
