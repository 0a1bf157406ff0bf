"""Callbacks the ``sm`` Lightning CLI adds to every recipe: stop at a non-finite loss, save on SIGTERM.

:class:`NonFiniteLossGuard` checks the loss before each backward pass: a NaN or infinite loss stops
training before it reaches the weights, with a :class:`~skeleton_mamba.errors.NonFiniteLossError`
naming the step, the batch and its samples (the ``sample_id`` / ``name`` entries of a dict batch, and
the batch rows whose tensors hold NaN or Inf). ``sm`` prints it on one line and exits with status 2.

:class:`InterruptRecorder` remembers how a run was stopped, so that ``sm`` can report it with its own
exit code (Lightning turns Ctrl-C into ``sys.exit(1)`` and SIGTERM into a ``SystemExit`` with code 0),
and on SIGTERM during ``fit`` saves ``last.ckpt`` in the checkpoint folder so ``--ckpt_path last``
resumes from the step where the run stopped.

:func:`check_trained` makes a ``fit`` that ran no training batch (an empty training set, or one smaller
than a batch with ``drop_last``) an error instead of a silent success with an empty run folder.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Any

import lightning.pytorch as pl
import torch
from lightning.pytorch.utilities.exceptions import SIGTERMException
from lightning_utilities.core import rank_zero

from skeleton_mamba.errors import InputError, NonFiniteLossError

__all__ = [
    "InterruptRecorder",
    "NonFiniteLossGuard",
    "check_trained",
    "describe_batch",
    "silence_interrupt_notice",
]

_ID_KEYS = ("sample_id", "name", "frame_dir", "motion_id")
MAX_LISTED = 8


def _rows_with_non_finite(batch: Any) -> set[int]:
    """Batch rows (first dimension) of any floating tensor in ``batch`` that hold NaN or Inf."""
    rows: set[int] = set()
    items = (
        batch.values() if isinstance(batch, dict) else batch if isinstance(batch, (list, tuple)) else [batch]
    )
    for item in items:
        if isinstance(item, torch.Tensor) and item.is_floating_point() and item.ndim >= 1:
            bad = ~torch.isfinite(item.detach().reshape(len(item), -1)).all(dim=1)
            rows.update(int(i) for i in bad.nonzero().flatten())
        elif isinstance(item, (dict, list, tuple)) and not isinstance(item, str):
            rows.update(_rows_with_non_finite(item))
    return rows


def describe_batch(batch: Any) -> str:
    """The batch's samples (ids when the batch carries them) and the rows that hold non-finite values."""
    ids: list[str] | None = None
    if isinstance(batch, dict):
        for key in _ID_KEYS:
            value = batch.get(key)
            if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
                ids = list(value)
                break
    bad = sorted(_rows_with_non_finite(batch))
    parts = []
    if ids is not None:
        shown = [ids[i] for i in bad] if bad else ids
        more = f" (+{len(shown) - MAX_LISTED} more)" if len(shown) > MAX_LISTED else ""
        parts.append(
            ("samples with NaN/Inf input: " if bad else "samples: ") + ", ".join(shown[:MAX_LISTED]) + more
        )
    elif bad:
        parts.append(f"batch rows with NaN/Inf input: {bad[:MAX_LISTED]}")
    else:
        parts.append("the inputs are finite (the model diverged: lower the learning rate)")
    return "; ".join(parts)


class NonFiniteLossGuard(pl.Callback):
    """Raise :class:`NonFiniteLossError` at the first NaN / Inf training loss, before the backward pass."""

    def __init__(self) -> None:
        self._batch: Any = None
        self._batch_idx = -1

    def on_train_batch_start(
        self, trainer: pl.Trainer, pl_module: pl.LightningModule, batch: Any, batch_idx: int
    ):
        self._batch, self._batch_idx = batch, batch_idx

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:
        self._batch = None  # do not keep the batch alive between steps

    def on_before_backward(
        self, trainer: pl.Trainer, pl_module: pl.LightningModule, loss: torch.Tensor
    ) -> None:
        value = float(loss.detach().float().sum())
        if math.isfinite(value):
            return
        raise NonFiniteLossError(
            f"training loss is {value} at epoch {trainer.current_epoch}, step {trainer.global_step}, "
            f"batch {self._batch_idx}; {describe_batch(self._batch)}. Training stopped before the update; "
            "the checkpoints written so far are intact"
        )


class InterruptRecorder(pl.Callback):
    """Record a Ctrl-C or SIGTERM that stopped the trainer; on SIGTERM in ``fit``, save ``last.ckpt``.

    Attributes:
        stopped_by: ``"interrupt"``, ``"sigterm"`` or ``None``.
        saved: the checkpoint written on SIGTERM (``None`` when none was written).
        new_run_dirs: the ``version_N`` folders this run created and their new parents (``runs/<name>/``,
            ``runs/``), deepest first: removed if the run fails before writing.
    """

    def __init__(self) -> None:
        self.stopped_by: str | None = None
        self.saved: str | None = None
        self.new_run_dirs: list[Path] = []  # set by the CLI: the run folders this run created

    def on_exception(
        self, trainer: pl.Trainer, pl_module: pl.LightningModule, exception: BaseException
    ) -> None:
        if isinstance(exception, KeyboardInterrupt):
            self.stopped_by = "interrupt"
        elif isinstance(exception, SIGTERMException):
            self.stopped_by = "sigterm"
            checkpoint = trainer.checkpoint_callback
            dirpath = getattr(checkpoint, "dirpath", None)
            if trainer.state.fn == "fit" and dirpath:
                path = os.path.join(dirpath, "last.ckpt")
                trainer.save_checkpoint(path, weights_only=False)  # the full state, for resuming
                self.saved = path


class _DropInterruptNotice(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return "Detected KeyboardInterrupt" not in record.getMessage()


def silence_interrupt_notice() -> None:
    """Drop Lightning's own Ctrl-C notice, so that ``sm``'s ``interrupted`` line is the only one."""

    logger = rank_zero.log  # the logger rank_zero_info writes to (Lightning sets it when imported)
    if not any(isinstance(f, _DropInterruptNotice) for f in logger.filters):
        logger.addFilter(_DropInterruptNotice())


def check_trained(trainer: pl.Trainer) -> None:
    """Raise an :class:`~skeleton_mamba.errors.InputError` when ``fit`` ran no training batch."""
    if trainer.num_training_batches != 0:
        return
    loader = trainer.train_dataloader
    dataset = getattr(loader, "dataset", None)
    try:
        samples = f"{len(dataset)} training samples"
    except TypeError:
        samples = "a training set of unknown size"
    batch = getattr(loader, "batch_size", None)
    drop = " with drop_last" if getattr(loader, "drop_last", False) else ""
    raise InputError(
        f"the training data gives no batch ({samples}, batch_size {batch}{drop}); nothing was trained"
    )
