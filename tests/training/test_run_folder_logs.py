"""The CSV logger's "exists and is not empty ... will be deleted" warning: only when it deletes something."""

from __future__ import annotations

import warnings

import pytest
from lightning.pytorch.loggers import CSVLogger, TensorBoardLogger

from skeleton_mamba.tasks.training.run_folders import open_csv_logs

MESSAGE = "Experiment logs directory .* exists and is not empty"


def _loggers(tmp_path):
    return [TensorBoardLogger(tmp_path, name="r", version=0), CSVLogger(tmp_path, name="r", version=0)]


def test_a_fresh_run_folder_with_a_tensorboard_event_file_gives_no_warning(tmp_path):
    tensorboard, csv = _loggers(tmp_path)
    tensorboard.log_hyperparams({"a": 1})  # writes the event file into version_0 first, as in a recipe
    tensorboard.experiment.flush()
    assert any((tmp_path / "r" / "version_0").iterdir())
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=MESSAGE)
        open_csv_logs([tensorboard, csv])
    csv.log_metrics({"x": 1.0}, step=0)
    csv.save()
    assert (tmp_path / "r" / "version_0" / "metrics.csv").is_file()


def test_the_warning_stays_when_an_old_metrics_csv_would_be_deleted(tmp_path):
    folder = tmp_path / "r" / "version_0"
    folder.mkdir(parents=True)
    (folder / "metrics.csv").write_text("step,x\n0,1.0\n")
    with pytest.warns(UserWarning, match=MESSAGE):
        open_csv_logs(_loggers(tmp_path))


def test_sm_fit_in_a_fresh_folder_prints_no_logs_directory_warning(tmp_path, monkeypatch, capsys):
    """The synthetic recognition recipe logs to TensorBoard and CSV in the same version_0."""
    from skeleton_mamba.tasks.training.cli import main as sm_main  # lazy: the test's own subject, heavy

    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = sm_main(
            ["fit", "--recipe", "recognition_synthetic.yaml", "--trainer.max_steps", "1"]
            + ["--trainer.enable_progress_bar", "false", "--trainer.limit_val_batches", "0"]
        )
    assert code == 0
    messages = [str(w.message) for w in caught] + capsys.readouterr().err.splitlines()
    assert not [m for m in messages if "exists and is not empty" in m], messages
    assert not [m for m in messages if "LeafSpec" in m], messages  # Lightning's own torch deprecation
    assert list((tmp_path / "runs").glob("*/version_0/metrics.csv"))
