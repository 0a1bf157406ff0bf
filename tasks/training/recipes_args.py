"""The command line of ``sm recipes`` (argparse only)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import command_parser

__all__ = ["build_parser"]


def build_parser() -> argparse.ArgumentParser:
    return command_parser(
        "sm recipes", "List the packaged recipes (sm fit --recipe NAME trains one; NAME.yaml or NAME)."
    )
