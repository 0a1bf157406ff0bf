"""Progress bars with epoch totals (``training/progress_bar.py``) and their installation by ``sm fit``."""

from __future__ import annotations

import re
import sys
from types import SimpleNamespace

import lightning.pytorch as pl
import pytest
from lightning.pytorch.callbacks import Callback, TQDMProgressBar

from skeleton_mamba.tasks.training import progress_bar
from skeleton_mamba.tasks.training.lightning_cli import SkeletonMambaCLI, import_task_modules
from skeleton_mamba.tasks.training.progress_bar import (
    EpochTotalRichProgressBar,
    EpochTotalTQDMProgressBar,
    StepClock,
    default_progress_bar,
    planned_steps,
    train_description,
)
from tests.helpers.cli_builds import build_cli
from tests.training.tiny_regression import TinyRegression


class ShownDescriptions(Callback):
    """Records the training bar's description at the first batch of every epoch (without the time left),
    and every description shown after a batch."""

    def __init__(self) -> None:
        self.shown: list[str] = []
        self.after_batches: list[str] = []

    @staticmethod
    def _description(trainer) -> str:
        bar = trainer.progress_bar_callback
        if isinstance(bar, TQDMProgressBar):
            return bar.train_progress_bar.desc.removesuffix(": ")
        return bar.progress.tasks[bar.train_progress_bar_id].description.strip()

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx) -> None:
        if batch_idx == 0:
            self.shown.append(re.sub(r" \(\d+:\d\d:\d\d left\)$", "", self._description(trainer)))

    def on_train_batch_end(self, trainer, *args) -> None:
        self.after_batches.append(self._description(trainer))


def fit(bar, shown=None, **trainer_args) -> tuple[pl.Trainer, list[str]]:
    shown = shown or ShownDescriptions()
    trainer = pl.Trainer(
        accelerator="cpu",
        callbacks=[bar, shown],
        logger=False,
        enable_checkpointing=False,
        enable_model_summary=False,
        **trainer_args,
    )
    trainer.fit(TinyRegression())
    return trainer, shown.shown


@pytest.mark.parametrize("bar_class", [EpochTotalTQDMProgressBar, EpochTotalRichProgressBar])
@pytest.mark.parametrize(
    ("trainer_args", "epochs_run"),
    [
        ({"max_steps": 10}, 4),  # 3 steps per epoch: epochs 0-3, the last one cut after 1 step
        ({"max_steps": 5, "accumulate_grad_batches": 2}, 3),  # 2 optimizer steps per epoch of 3 batches
        ({"max_epochs": 2}, 2),
    ],
)
def test_the_bar_shows_the_number_of_epochs_the_run_takes(bar_class, trainer_args, epochs_run):
    if bar_class is EpochTotalRichProgressBar:
        pytest.importorskip("rich")
    _, shown = fit(bar_class(), **trainer_args)
    # every epoch that ran was announced as "Epoch e/last" with last the index of the last epoch run
    assert shown == [f"Epoch {e}/{epochs_run - 1}" for e in range(epochs_run)]


@pytest.mark.parametrize("bar_class", [EpochTotalTQDMProgressBar, EpochTotalRichProgressBar])
def test_the_bar_shows_the_time_the_whole_run_has_left(bar_class):
    if bar_class is EpochTotalRichProgressBar:
        pytest.importorskip("rich")
    shown = ShownDescriptions()
    fit(bar_class(), shown, max_steps=10)
    # after each batch: the epoch and the run's time left (a tiny model: 0:00:00)
    assert len(shown.after_batches) == 10
    assert all(re.fullmatch(r"Epoch [0-3]/3 \(0:00:0\d left\)", d) for d in shown.after_batches), shown


def test_step_clock_extrapolates_the_mean_step_time(monkeypatch):
    now = [100.0]
    monkeypatch.setattr(progress_bar.time, "monotonic", lambda: now[0])
    trainer = SimpleNamespace(
        num_training_batches=11, accumulate_grad_batches=1, max_steps=400, max_epochs=None, global_step=0
    )
    assert planned_steps(trainer) == 400
    clock = StepClock()
    assert clock.left(trainer) is None  # not started
    clock.start(trainer)
    assert clock.left(trainer) is None  # no step timed yet
    now[0], trainer.global_step = 130.0, 20  # 20 steps in 30 s: 380 left at 1.5 s
    assert clock.left(trainer).total_seconds() == 570
    assert train_description(trainer, 1, clock) == "Epoch 1/36 (0:09:30 left)"
    epochs = SimpleNamespace(num_training_batches=3, accumulate_grad_batches=1, max_steps=-1, max_epochs=20)
    assert planned_steps(epochs) == 60  # humanml3d_demo: 20 epochs of 3 steps


def test_a_time_bounded_run_shows_the_time_left():
    trainer = pl.Trainer(max_time="00:00:02:00", logger=False, enable_checkpointing=False)
    # no max_epochs (Lightning's fit loop makes it -1: its rich bar read "Epoch 14/-2")
    assert train_description(trainer, 14) == "Epoch 14 (0:02:00 left)"


def cli_trainer(args: list[str]) -> pl.Trainer:
    import_task_modules()
    return build_cli(SkeletonMambaCLI, args).trainer


def test_sm_installs_the_bar_unless_the_recipe_has_one_or_turns_it_off(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["sm"])  # the arguments are passed as args=
    recipe = ["--recipe", "recognition_synthetic.yaml", "--trainer.max_steps", "300"]
    bar = cli_trainer(recipe).progress_bar_callback
    assert type(bar) is type(default_progress_bar())
    assert cli_trainer([*recipe, "--trainer.enable_progress_bar", "false"]).progress_bar_callback is None
    own = tmp_path / "own_bar.yaml"
    own.write_text(
        "trainer:\n  callbacks:\n    - class_path: lightning.pytorch.callbacks.TQDMProgressBar\n"
        "      init_args: {refresh_rate: 7}\n"
    )
    kept = cli_trainer([*recipe, "--config", str(own)]).progress_bar_callback
    assert type(kept) is TQDMProgressBar and kept.refresh_rate == 7


class RecreatedTask(Callback):
    """Drops the rich bar's training task after the first batch, as a mid-epoch resume starts without one;
    records the description of the task Lightning then creates at the batch's end."""

    def __init__(self) -> None:
        self.shown: list[str] = []

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx) -> None:
        bar = trainer.progress_bar_callback
        if batch_idx == 1 and trainer.current_epoch == 0:
            bar.train_progress_bar_id = None
        if batch_idx == 2 and trainer.current_epoch == 0:
            self.shown.append(bar.progress.tasks[bar.train_progress_bar_id].description.strip())


def test_the_rich_bar_keeps_its_theme_and_describes_a_task_created_mid_epoch():
    pytest.importorskip("rich")
    from lightning.pytorch.callbacks.progress.rich_progress import RichProgressBarTheme

    _, shown = fit(EpochTotalRichProgressBar(theme=RichProgressBarTheme(description="green")), max_steps=5)
    assert shown == ["[green]Epoch 0/1", "[green]Epoch 1/1"]  # markup as Lightning's tasks get it
    recreated = RecreatedTask()
    trainer = pl.Trainer(
        accelerator="cpu", callbacks=[EpochTotalRichProgressBar(), recreated], logger=False,
        enable_checkpointing=False, enable_model_summary=False, max_steps=4,
    )  # fmt: skip
    trainer.fit(TinyRegression())
    assert recreated.shown == ["Epoch 0/1 (0:00:00 left)"]  # a tiny model: no time left


class LiveAtFitEnd(Callback):
    """Records whether the rich bar's live display still runs when ``on_fit_end`` callbacks print."""

    def on_fit_end(self, trainer, pl_module) -> None:
        self.live = trainer.progress_bar_callback.progress.live.is_started


def test_the_rich_bar_is_stopped_before_fit_end_callbacks_print():
    pytest.importorskip("rich")
    probe = LiveAtFitEnd()
    trainer = pl.Trainer(
        accelerator="cpu", callbacks=[EpochTotalRichProgressBar(), probe], logger=False,
        enable_checkpointing=False, enable_model_summary=False, max_steps=2,
    )  # fmt: skip
    trainer.fit(TinyRegression())
    assert probe.live is False
