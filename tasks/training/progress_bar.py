"""Training progress bars that show how many epochs the run will take, however it is bounded.

Lightning's bars write the epoch as ``Epoch e/{max_epochs - 1}`` (rich) or ``Epoch e`` (tqdm). A recipe
bounded by ``max_steps`` (or ``max_time``) leaves ``max_epochs`` unset, which Lightning turns into -1, so
the rich bar read ``Epoch 14/-2``. Here the last epoch is ``max_epochs - 1`` when set, else derived from
``max_steps`` and the optimizer steps per epoch (``ceil(num_training_batches / accumulate_grad_batches)``).
The description also says how long the whole run has left (Lightning's own bars time one epoch): the
optimizer steps still to go times the mean time of those done so far (:class:`StepClock`), so a slow or
busy machine shows a longer wait instead of a shorter run. A run bounded only by time shows the time
left under ``max_time``. ``sm fit`` installs :func:`default_progress_bar` unless the recipe configures a
progress bar or turns it off (``tasks/training/lightning_cli.py``): a live bar on a terminal, and where the
output goes to a log file or a pipe (no terminal to redraw a bar on) :class:`PlainProgressLog`, plain lines
without carriage returns.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from datetime import timedelta

import lightning.pytorch as pl
from lightning.pytorch.callbacks import Callback, ProgressBar, RichProgressBar, TQDMProgressBar
from lightning.pytorch.callbacks.timer import Timer

from skeleton_mamba.tasks.motion.commands.cli_options import progress_default

__all__ = [
    "EpochTotalRichProgressBar",
    "EpochTotalTQDMProgressBar",
    "PlainProgressLog",
    "StepClock",
    "default_progress_bar",
    "live_bars_shown",
    "planned_steps",
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


def planned_steps(trainer: pl.Trainer) -> int | None:
    """The optimizer steps the run takes: ``max_steps``, else ``max_epochs`` times the steps per epoch."""
    batches = trainer.num_training_batches
    if not 0 < batches < math.inf:
        return None
    per_epoch = math.ceil(batches / trainer.accumulate_grad_batches)
    bounds = []
    if trainer.max_steps is not None and trainer.max_steps > 0:
        bounds.append(trainer.max_steps)
    if trainer.max_epochs is not None and trainer.max_epochs > 0:
        bounds.append(trainer.max_epochs * per_epoch)
    return min(bounds) if bounds else None


class StepClock:
    """Estimates the run's time left from the optimizer steps done since :meth:`start`."""

    def __init__(self) -> None:
        self.started: float | None = None
        self.first_step = 0

    def start(self, trainer: pl.Trainer) -> None:
        self.started, self.first_step = time.monotonic(), trainer.global_step

    def left(self, trainer: pl.Trainer) -> timedelta | None:
        """(steps to go) x (mean seconds per step so far); None before the first step or without a bound."""
        total, done = planned_steps(trainer), trainer.global_step - self.first_step
        if self.started is None or total is None or done < 1:
            return None
        per_step = (time.monotonic() - self.started) / done
        return timedelta(seconds=round(max(total - trainer.global_step, 0) * per_step))


def _time_left(trainer: pl.Trainer) -> timedelta | None:
    """The training time left under ``max_time`` (its :class:`Timer`), None without a time limit."""
    for callback in trainer.callbacks:
        if isinstance(callback, Timer):
            left = callback.time_remaining("train")
            return None if left is None else timedelta(seconds=round(left))
    return None


def train_description(trainer: pl.Trainer, epoch: int, clock: StepClock | None = None) -> str:
    """``Epoch e/last`` (0-based, as Lightning writes it), ``Epoch e (h:mm:ss left)`` or ``Epoch e``;
    ``Epoch e/last (h:mm:ss left)`` once ``clock`` has timed a step."""
    total = planned_epochs(trainer)
    left = clock.left(trainer) if clock is not None else None
    if total is None:
        left = _time_left(trainer)
    text = f"Epoch {epoch}/{total - 1}" if total is not None else f"Epoch {epoch}"
    return f"{text} ({left} left)" if left is not None else text


class EpochTotalRichProgressBar(RichProgressBar):
    """Lightning's rich progress bar with :func:`train_description`.

    The training task's description is replaced once Lightning has created or reset it (at every epoch
    start, and at the first batch when training resumes mid-epoch), and after every batch (the time
    left), through the bar's public ``progress`` (a rich ``Progress``) and ``train_progress_bar_id``.
    """

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.clock = StepClock()

    def on_train_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        super().on_train_start(trainer, pl_module)
        self.clock.start(trainer)

    def on_train_epoch_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        super().on_train_epoch_start(trainer, pl_module)
        self._describe_train_task(trainer)

    def on_train_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        """Stop the live display when training ends: Lightning stops it at ``teardown``, after
        ``on_fit_end``, so whatever a callback printed there (the demos' score tables) was followed by
        the bar redrawn half-way. ``teardown`` is idempotent (rich's ``Live.stop`` returns once stopped)."""
        super().on_train_end(trainer, pl_module)
        self.teardown(trainer, pl_module, "fit")

    def on_train_batch_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule, *args, **kwargs) -> None:
        created = self.train_progress_bar_id is None  # Lightning adds the task here after a mid-epoch resume
        if not created:
            self._describe_train_task(trainer, refresh=False)  # drawn by Lightning's refresh below
        super().on_train_batch_end(trainer, pl_module, *args, **kwargs)
        if created:
            self._describe_train_task(trainer)

    def _describe_train_task(self, trainer: pl.Trainer, refresh: bool = True) -> None:
        if self.is_disabled or self.progress is None or self.train_progress_bar_id is None:
            return
        text = train_description(trainer, trainer.current_epoch, self.clock)
        text = f"{text:{len(self.validation_description)}}"  # padded as Lightning pads it (no flicker)
        if self.theme.description:  # styled as Lightning styles the descriptions of the tasks it adds
            text = f"[{self.theme.description}]{text}"
        self.progress.update(self.train_progress_bar_id, description=text)
        if refresh:
            self.refresh()


class EpochTotalTQDMProgressBar(TQDMProgressBar):
    """Lightning's tqdm progress bar with :func:`train_description` (updated after every batch)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.clock = StepClock()

    def on_train_start(self, trainer: pl.Trainer, *args) -> None:
        super().on_train_start(trainer, *args)
        self.clock.start(trainer)

    def on_train_epoch_start(self, trainer: pl.Trainer, *args) -> None:
        super().on_train_epoch_start(trainer, *args)
        self.train_progress_bar.set_description(train_description(trainer, trainer.current_epoch, self.clock))

    def on_train_batch_end(self, trainer: pl.Trainer, *args, **kwargs) -> None:
        description = train_description(trainer, trainer.current_epoch, self.clock)
        self.train_progress_bar.set_description(description, refresh=False)  # drawn by the update below
        super().on_train_batch_end(trainer, *args, **kwargs)


class PlainProgressLog(ProgressBar):
    """The progress of a run as plain lines on stderr, for a log file or a pipe: no carriage returns, no
    redrawn bar. One line at the end of every training epoch, and one every ``interval`` seconds within a
    long epoch or evaluation::

        Epoch 3/9 (0:01:20 left): batch 120/120, train/loss 1.23, val/top1 0.812
        Predicting: batch 40/100
    """

    def __init__(self, interval: float = 30.0) -> None:
        super().__init__()
        self.interval = interval
        self.enabled = True
        self.clock = StepClock()
        self.last_line = time.monotonic()

    def disable(self) -> None:
        self.enabled = False

    def enable(self) -> None:
        self.enabled = True

    def print(self, *args, **kwargs) -> None:
        print(*args, **{"file": sys.stderr, **kwargs})

    def _line(self, text: str) -> None:
        if self.enabled:
            self.print(text, flush=True)
            self.last_line = time.monotonic()

    def _due(self) -> bool:
        return self.enabled and time.monotonic() - self.last_line >= self.interval

    def _metrics(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> str:
        parts = []
        for name, value in self.get_metrics(trainer, pl_module).items():
            if name == "v_num":
                continue
            value = value.item() if hasattr(value, "item") else value
            parts.append(f"{name} {value:.4g}" if isinstance(value, float) else f"{name} {value}")
        return "".join(f", {part}" for part in parts)

    def _train_line(self, trainer: pl.Trainer, pl_module: pl.LightningModule, batches: int) -> None:
        total = self.total_train_batches
        of = f"/{total}" if total != math.inf else ""
        description = train_description(trainer, trainer.current_epoch, self.clock)
        self._line(f"{description}: batch {batches}{of}{self._metrics(trainer, pl_module)}")

    def on_train_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        self.clock.start(trainer)
        self.last_line = time.monotonic()

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx: int) -> None:
        if self._due():
            self._train_line(trainer, pl_module, batch_idx + 1)

    def on_train_epoch_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        self._train_line(trainer, pl_module, trainer.fit_loop.epoch_loop.batch_progress.current.ready)

    def _eval_batch_end(self, description: str, batch_idx: int, totals: list, dataloader_idx: int) -> None:
        if self._due():
            total = totals[dataloader_idx] if dataloader_idx < len(totals) else math.inf
            of = f"/{total}" if total != math.inf else ""
            self._line(f"{description}: batch {batch_idx + 1}{of}")

    def on_validation_batch_end(self, trainer, pl_module, outputs, batch, batch_idx, dataloader_idx=0):
        self._eval_batch_end(self.validation_description, batch_idx, trainer.num_val_batches, dataloader_idx)

    def on_test_batch_end(self, trainer, pl_module, outputs, batch, batch_idx, dataloader_idx=0):
        self._eval_batch_end(self.test_description, batch_idx, trainer.num_test_batches, dataloader_idx)

    def on_predict_batch_end(self, trainer, pl_module, outputs, batch, batch_idx, dataloader_idx=0):
        self._eval_batch_end(self.predict_description, batch_idx, trainer.num_predict_batches, dataloader_idx)


def live_bars_shown() -> bool:
    """Whether a live (redrawn) bar has a terminal to draw on: stderr (tqdm's) and stdout (rich's) both."""
    return progress_default(sys.stderr) and progress_default(sys.stdout)


def default_progress_bar() -> ProgressBar:
    """On a terminal the bar Lightning would pick (rich when installed, else tqdm) with epoch totals;
    elsewhere :class:`PlainProgressLog`."""
    if not live_bars_shown():
        return PlainProgressLog()
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
