"""The command line of ``sm export-pretrained`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import command_parser
from skeleton_mamba.tasks.motion.io.output_folder import OVERWRITE_HELP

__all__ = ["build_parser"]

EXAMPLES = """examples:
  sm export-pretrained --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt --out emm-demo/
  sm export-pretrained --ckpt last.ckpt --out emm-demo/ --push-to-hub my-org/emm-demo"""


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm export-pretrained",
        "Write a Lightning checkpoint as a Hugging Face from_pretrained folder: config.json, "
        "model.safetensors, the model card README.md and module.safetensors (what sm dance / generate / "
        "stream / predict need to rebuild the module from the folder).",
        EXAMPLES,
    )
    p.add_argument("--ckpt", required=True, help="a Lightning checkpoint (.ckpt) of a task recipe")
    p.add_argument(
        "--out",
        required=True,
        help="the folder to write (created; an existing one must be an earlier export)",
    )
    p.add_argument(
        "--module", default=None, help="the LightningModule class path, when the checkpoint names none"
    )
    p.add_argument(
        "--recipe", default=None, help="the recipe the model was trained with (for the model card)"
    )
    p.add_argument(
        "--push-to-hub", default=None, metavar="ORG/NAME", help="also upload the folder to the Hub"
    )
    p.add_argument("--private", action="store_true", help="create the Hub repository private")
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    return p
