"""Building a LightningCLI without running a subcommand, as the tests of its parsing and setup need."""

from __future__ import annotations

from lightning.pytorch import LightningDataModule, LightningModule
from lightning.pytorch.cli import LightningCLI


def build_cli(cli_class: type[LightningCLI], args: list[str]) -> LightningCLI:
    """``cli_class`` parsed from ``args`` (any LightningModule and LightningDataModule subclass, as ``sm``
    takes them) with its trainer, model and data module instantiated; nothing run."""
    return cli_class(
        LightningModule,
        LightningDataModule,
        subclass_mode_model=True,
        subclass_mode_data=True,
        run=False,
        args=args,
    )
