"""Training progress bars that show how many epochs the run will take, however it is bounded.

Lightning's bars write the epoch as ``Epoch e/{max_epochs - 1}`` (rich) or ``Epoch e`` (tqdm). A recipe
bounded by ``max_steps`` (or ``max_time``) leaves ``max_epochs`` unset, which Lightning turns into -1, so
the rich bar read ``Epoch 14/-2``. Here the last epoch is ``max_epochs - 1`` when set, else derived from
``max_steps`` and the optimizer steps per epoch (``ceil(num_training_batches / accumulate_grad_batches)``);
a run bounded only by time shows the time left. ``sm fit`` installs :func:`default_progress_bar` unless
the recipe configures a progress bar or turns it off (``tasks/training/lightning_cli.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from datetime import timedelta

import lightning.pytorch as pl
from lightning.pytorch.callbacks import Callback, ProgressBar, RichProgressBar, TQDMProgressBar
from lightning.pytorch.callbacks.timer import Timer

__all__ = [
    "EpochTotalRichProgressBar",
    "EpochTotalTQDMProgressBar",
    "default_progress_bar",
    "planned_epochs",
    "train_description",
    "with_default_progress_bar",
]


def planned_epochs(trainer: pl.Trainer) -> int | None:
    """How many epochs the run takes: ``max_epochs``, else ``ceil(max_steps / steps per epoch)``.

    None when neither bounds the run (a ``max_time``-only run) or the epoch length is unknown.
    """
    if trainer.max_epochs is not None and trainer.max_epochs > 0:
        return trainer.max_epochs
    batches = trainer.num_training_batches
    if trainer.max_steps is None or trainer.max_steps <= 0 or not 0 < batches < math.inf:
        return None
    steps_per_epoch = math.ceil(batches / trainer.accumulate_grad_batches)
    return math.ceil(trainer.max_steps / steps_per_epoch)


def _time_left(trainer: pl.Trainer) -> timedelta | None:
    """The training time left under ``max_time`` (its :class:`Timer`), None without a time limit."""
    for callback in trainer.callbacks:
        if isinstance(callback, Timer):
            left = callback.time_remaining("train")
            return None if left is None else timedelta(seconds=round(left))
    return None


def train_description(trainer: pl.Trainer, epoch: int) -> str:
    """``Epoch e/last`` (0-based, as Lightning writes it), ``Epoch e (h:mm:ss left)`` or ``Epoch e``."""
    total = planned_epochs(trainer)
    if total is not None:
        return f"Epoch {epoch}/{total - 1}"
    left = _time_left(trainer)
    return f"Epoch {epoch} ({left} left)" if left is not None else f"Epoch {epoch}"


class EpochTotalRichProgressBar(RichProgressBar):
    """Lightning's rich progress bar with :func:`train_description`.

    The training task's description is replaced once Lightning has created or reset it (at every epoch
    start, and at the first batch when training resumes mid-epoch), through the bar's public ``progress``
    (a rich ``Progress``) and ``train_progress_bar_id``.
    """

    def on_train_epoch_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        super().on_train_epoch_start(trainer, pl_module)
        self._describe_train_task(trainer)

    def on_train_batch_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule, *args, **kwargs) -> None:
        created = self.train_progress_bar_id is None  # Lightning adds the task here after a mid-epoch resume
        super().on_train_batch_end(trainer, pl_module, *args, **kwargs)
        if created:
            self._describe_train_task(trainer)

    def _describe_train_task(self, trainer: pl.Trainer) -> None:
        if self.is_disabled or self.progress is None or self.train_progress_bar_id is None:
            return
        text = train_description(trainer, trainer.current_epoch)
        text = f"{text:{len(self.validation_description)}}"  # padded as Lightning pads it (no flicker)
        if self.theme.description:  # styled as Lightning styles the descriptions of the tasks it adds
            text = f"[{self.theme.description}]{text}"
        self.progress.update(self.train_progress_bar_id, description=text)
        self.refresh()


class EpochTotalTQDMProgressBar(TQDMProgressBar):
    """Lightning's tqdm progress bar with :func:`train_description`."""

    def on_train_epoch_start(self, trainer: pl.Trainer, *args) -> None:
        super().on_train_epoch_start(trainer, *args)
        self.train_progress_bar.set_description(train_description(trainer, trainer.current_epoch))


def default_progress_bar() -> ProgressBar:
    """The bar Lightning would pick (rich when installed, else tqdm), with epoch totals."""
    try:
        return EpochTotalRichProgressBar()
    except ModuleNotFoundError:  # RichProgressBar's own check: rich missing or too old
        return EpochTotalTQDMProgressBar()


def with_default_progress_bar(
    callbacks: Callback | Sequence[Callback] | None, enable_progress_bar: bool | None
) -> list[Callback]:
    """``callbacks`` plus :func:`default_progress_bar`, unless one is configured or bars are turned off."""
    if callbacks is None:
        callbacks = []
    elif isinstance(callbacks, Callback):
        callbacks = [callbacks]
    callbacks = list(callbacks)
    if enable_progress_bar is not False and not any(isinstance(c, ProgressBar) for c in callbacks):
        callbacks.append(default_progress_bar())
    return callbacks
