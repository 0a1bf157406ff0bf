"""The command line of ``sm export-web`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import command_parser
from skeleton_mamba.tasks.motion.io.output_folder import OVERWRITE_HELP
from skeleton_mamba.tasks.motion.retarget.rig_output import add_rig_arguments

__all__ = ["QUANTIZE_CHOICES", "build_parser"]

QUANTIZE_CHOICES = ("none", "int8", "int4")  # sm export-web --quantize (tasks/stream/web_quantize.py)

EXAMPLES = """examples:
  sm export-web --ckpt runs/stream_dance_demo/version_0/checkpoints/last.ckpt --out site/
  sm export-web --ckpt my-dancer/ --out site/ --ort-web onnxruntime-web-1.31.1.tgz   # no npm, no network
  sm export-web --ckpt my-dancer/ --out site/ --rig avatar.vrm    # your character dances in the page
  sm export-web --ckpt my-dancer/ --out site/ --quantize int8     # int8 weights: a smaller, faster page
  python -m http.server -d site/     # or open site/index.html from disk"""


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm export-web",
        "Write a static page where the streaming dancer dances in the browser: its step and music front end "
        "as one ONNX graph run by onnxruntime-web (wasm), the three.js skeleton, a music file or the "
        "microphone as input. One HTML file; opens from disk or any static server, no network request.",
        EXAMPLES,
    )
    p.add_argument(
        "--ckpt", required=True, help="a streaming-dancer checkpoint, or its from_pretrained folder"
    )
    p.add_argument("--out", required=True, help="the folder to write (index.html and the licences)")
    p.add_argument(
        "--ort-web",
        default=None,
        help="the npm tarball onnxruntime-web-1.31.1.tgz (default: the cache; npm pack fetches it)",
    )
    add_rig_arguments(
        p,
        "your character (a skinned .glb or .vrm 0.x / 1.0): the page's dancer drives it, its own mesh, "
        "instead of the skeleton (bones found as sm retarget finds them)",
    )
    p.add_argument(
        "--three-vrm",
        default=None,
        help="with a VRM --rig: the npm tarball pixiv-three-vrm-3.5.5.tgz (default: the cache; npm pack "
        "fetches it)",
    )
    p.add_argument(
        "--quantize",
        choices=QUANTIZE_CHOICES,
        default="none",
        help="the graph's Linear weights, quantized by onnxruntime's tools after the float32 export: int8 "
        "(per channel), int4 (blocks of 32); the page names its precision (default: none, float32)",
    )
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    return p
