"""Writing a module as a Lightning-style checkpoint file, as the tests of the checkpoint readers need."""

from __future__ import annotations

from pathlib import Path

import lightning
import torch


def save_module_checkpoint(module: lightning.LightningModule, path: Path, **extra) -> Path:
    """``module``'s state_dict and hyper-parameters (as ``Trainer.save_checkpoint`` names them) saved at
    ``path``, with ``extra`` top-level entries (e.g. ``datamodule_hyper_parameters``); returns ``path``."""
    checkpoint = {
        "state_dict": module.state_dict(),
        "hyper_parameters": dict(module.hparams),
        "pytorch-lightning_version": lightning.__version__,
        **extra,
    }
    torch.save(checkpoint, path)
    return path
