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


def tiny_stream_checkpoint(path: Path, music: torch.Tensor | None = None) -> tuple[Path, torch.nn.Module]:
    """A tiny causal streaming dancer (random weights, seed 0, the demo recipe's 8-stage low-pass) saved at
    ``path``, with the music statistics of ``music`` (T, 34) when given; returns the path and its network."""
    from skeleton_mamba.tasks.stream.module import StreamDanceModule  # lazy: only the stream tests need it

    torch.manual_seed(0)
    tiny = {"dim": 16, "depth": 1, "heads": 2, "mlp_dim": 32, "mixer": {"d_state": 16, "headdim": 8}}
    module = StreamDanceModule(backbone={**tiny, "causal": True}, smoothing_stages=8)
    if music is not None:
        module.model.set_music_statistics(music)
    return save_module_checkpoint(module, path), module.model.eval()
