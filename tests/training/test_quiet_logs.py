"""Quiet logs: a fit prints no Lightning advert and no ``Total FLOPs: 0``, its progress in a log file is plain
lines (no carriage returns), ``sm export-onnx`` prints no torchvision lines and no LeafSpec FutureWarning,
and only those known messages are silenced."""

from __future__ import annotations

import copy
import logging
import os
import re
import subprocess
import sys
import warnings

import lightning.pytorch as pl
import pytest

from skeleton_mamba.tasks.training import progress_bar
from skeleton_mamba.tasks.training.library_noise import LIBRARY_LOG_LINES, silence_library_noise
from skeleton_mamba.tasks.training.lightning_cli import quiet_as_trainer_option
from skeleton_mamba.tasks.training.model_summary import (
    ParameterSummary,
    summary_table,
    with_parameter_summary,
)
from skeleton_mamba.tasks.training.progress_bar import PlainProgressLog, default_progress_bar
from tests.training.tiny_regression import TinyRegression as Regression


class Recorded(logging.Handler):
    """Collects the messages that reach ``names``' loggers (past their filters), whatever they propagate."""

    def __init__(self, *names: str) -> None:
        super().__init__(logging.DEBUG)
        self.names, self.messages = names, []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())

    def __enter__(self) -> Recorded:
        for name in self.names:
            logging.getLogger(name).addHandler(self)
        return self

    def __exit__(self, *exc) -> None:
        for name in self.names:
            logging.getLogger(name).removeHandler(self)


def sm_executable() -> str:
    path = os.path.join(os.path.dirname(sys.executable), "sm")
    if not os.path.exists(path):
        pytest.skip(f"console script not installed at {path}")
    return path


EXPORTER = "torch.onnx._internal.exporter._registration"
RANK_ZERO = "lightning.pytorch.utilities.rank_zero"


def test_a_fit_writes_no_advert_no_flops_line_and_no_carriage_return_to_a_log(tmp_path):
    """A real ``sm fit`` with stdout and stderr to pipes, as in a log file."""
    args = [
        "fit", "--recipe", "recognition_synthetic.yaml", "--trainer.max_epochs", "2",
        "--trainer.limit_train_batches", "2", "--trainer.limit_val_batches", "1",
    ]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        [sm_executable(), *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-3000:]
    assert "\r" not in output
    for removed in ("litlogger", "💡", "Total FLOPs", "FLOPs", "Skipping setting a default `ModelSummary`"):
        assert removed not in output, removed
    assert re.search(r"^81\.0 K +Total params$", done.stderr, re.M)  # the summary is still there
    epochs = re.findall(
        r"^Epoch (\d)/1 \(\d:\d\d:\d\d left\): batch 2/2, .*train/loss [0-9.]+", done.stderr, re.M
    )
    assert epochs == ["0", "1"], done.stderr  # one plain line per epoch
    assert "FutureWarning" not in output


def test_sm_fit_quiet_is_the_trainers_switch():
    assert quiet_as_trainer_option(["fit", "--recipe", "r.yaml", "--quiet"]) == [
        "fit", "--recipe", "r.yaml", "--trainer.enable_progress_bar", "false",
    ]  # fmt: skip
    assert quiet_as_trainer_option(["fit", "--recipe", "r.yaml"]) == ["fit", "--recipe", "r.yaml"]


class TinyRegression(Regression):
    """test_progress_bar's linear model, logging its loss to the progress bar."""

    def training_step(self, batch, batch_idx):
        loss = super().training_step(batch, batch_idx)
        self.log("train/loss", loss, prog_bar=True)
        return loss


def test_the_plain_progress_log_prints_lines_per_epoch_and_when_due(capsys):
    trainer = pl.Trainer(
        accelerator="cpu", callbacks=[PlainProgressLog(interval=0.0)], logger=False,
        enable_checkpointing=False, enable_model_summary=False, max_epochs=2,
    )  # fmt: skip
    trainer.fit(TinyRegression())
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = [line for line in err.splitlines() if line.startswith("Epoch")]
    # interval 0: a line after every batch, and one at every epoch's end
    batches = [
        re.match(r"Epoch (\d)/1 \(\d:\d\d:\d\d left\): batch (\d)/3, train/loss [0-9.e-]+$", x) for x in lines
    ]
    assert all(batches), lines
    assert [(m.group(1), m.group(2)) for m in batches] == [
        ("0", "1"), ("0", "2"), ("0", "3"), ("0", "3"), ("1", "1"), ("1", "2"), ("1", "3"), ("1", "3"),
    ]  # fmt: skip


def test_the_default_bar_is_live_on_a_terminal_and_plain_elsewhere(monkeypatch):
    monkeypatch.setattr(progress_bar, "live_bars_shown", lambda: False)
    assert type(default_progress_bar()) is PlainProgressLog
    monkeypatch.setattr(progress_bar, "live_bars_shown", lambda: True)
    assert type(default_progress_bar()) in (
        progress_bar.EpochTotalRichProgressBar,
        progress_bar.EpochTotalTQDMProgressBar,
    )


def test_the_summary_lists_flops_only_when_they_were_counted():
    columns = [(" ", ["0", "1"]), ("Name", ["model", "head"]), ("Params", ["81.0 K", "1.2 K"])]
    table = summary_table(columns, 82_200, 82_200, 0.3288, {"train": 2, "eval": 0})
    lines = table.splitlines()
    assert (
        lines[0] == "  | Name  | Params"
        and lines[2] == "0 | model | 81.0 K"
        and lines[3] == "1 | head  | 1.2 K"
    )
    assert set(lines[1]) == {"-"} and lines[1] == lines[4]
    assert "82.2 K     Total params" in lines and "0.329      Total estimated model params size (MB)" in lines
    assert "FLOPs" not in table
    counted = summary_table(columns, 82_200, 82_200, 0.3288, {"train": 2, "eval": 0}, total_flops=1_500_000)
    assert counted.splitlines()[-1] == "1.5 M      Total FLOPs"


def test_sm_installs_its_summary_unless_the_recipe_has_one_or_turns_it_off():
    callbacks, enabled = with_parameter_summary([], None)
    assert [type(c) for c in callbacks] == [ParameterSummary] and enabled is False  # Lightning adds none
    own = pl.callbacks.ModelSummary(max_depth=2)
    assert with_parameter_summary([own], True) == ([own], True)
    assert with_parameter_summary([], False) == ([], False)


def test_the_parameter_summary_of_a_fit_has_no_flops_column():
    trainer = pl.Trainer(
        accelerator="cpu", callbacks=[ParameterSummary()], logger=False, enable_checkpointing=False,
        enable_model_summary=False, enable_progress_bar=False, max_steps=1,
    )  # fmt: skip
    with Recorded(RANK_ZERO) as recorded:
        trainer.fit(TinyRegression())
    summary = next(m for m in recorded.messages if "Total params" in m)
    assert [c.strip() for c in summary.splitlines()[1].split("|")] == ["", "Name", "Type", "Params", "Mode"]
    assert "FLOPs" not in summary and "3          Total params" in summary  # 2 weights + 1 bias


def test_only_the_known_library_messages_are_silenced():
    silence_library_noise()
    silence_library_noise()  # repeatable: one filter per logger
    exporter = logging.getLogger(EXPORTER)
    assert len([f for f in exporter.filters if type(f).__name__ == "_DropMatching"]) == 1
    with Recorded(EXPORTER, RANK_ZERO) as recorded:
        exporter.warning("torchvision is not installed. Skipping %s", "torchvision::nms")
        exporter.warning("some other exporter warning")
        advert = "💡 Tip: For seamless cloud logging and experiment tracking, try installing [litlogger]"
        logging.getLogger(RANK_ZERO).info(advert)
        logging.getLogger(RANK_ZERO).info("GPU available: False, used: False")
    assert recorded.messages == ["some other exporter warning", "GPU available: False, used: False"]


def test_the_silenced_logger_names_are_the_libraries_own():
    from lightning.pytorch.utilities import rank_zero as pytorch_rank_zero
    from lightning_utilities.core import rank_zero as shared_rank_zero
    from torch.onnx._internal.exporter import _registration

    names = {name for name, _ in LIBRARY_LOG_LINES}
    assert _registration.logger.name in names
    assert shared_rank_zero.log.name in names  # the logger rank_zero_info writes to
    assert pytorch_rank_zero.__name__ in names


def test_the_leaf_spec_warning_of_a_deep_copy_is_silenced_and_others_are_not():
    from torch.utils._pytree import treespec_leaf

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        copy.deepcopy(treespec_leaf())  # what torch.export does to a tree spec (the warning's source)
    assert any("LeafSpec" in str(w.message) for w in caught)  # torch still warns: the filter is needed
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        silence_library_noise()
        copy.deepcopy(treespec_leaf())
        warnings.warn("an unrelated future change", FutureWarning, stacklevel=1)
    assert [str(w.message) for w in caught] == ["an unrelated future change"]
