"""Run folders ``<save_dir>/<name>/version_N``: ``--ckpt_path last``, resuming in place, no empty folders.

- ``--ckpt_path last`` means the last checkpoint of the latest run of the same recipe: the highest
  ``version_N`` under the recipe's logger folder that holds a checkpoint, its ``last.ckpt`` (else its
  newest ``*.ckpt``). No such run is an error, never a silent start from scratch.
- ``sm fit --ckpt_path runs/<name>/version_N/checkpoints/X.ckpt`` continues in ``version_N``: the
  recipe's loggers get ``version: N``, so logs and checkpoints go on in the run's own folder. Lightning's
  CSV logger deletes an existing ``metrics.csv`` when it opens a folder, so that file is first renamed to
  ``metrics.before_resume_<k>.csv``.
- A run that fails before writing anything but logger bookkeeping (``config.yaml``, ``hparams.yaml``,
  an event file, ``metrics.csv``) leaves no ``version_N`` folder behind (:func:`remove_if_empty`).
- The CSV loggers open their folder first (:func:`open_csv_logs`): Lightning's CSV logger warns "Experiment
  logs directory ... exists and is not empty ... will be deleted" whenever the folder holds any file (in a
  fresh run, the TensorBoard logger's event file in the same folder); opened first, it warns only when there
  is a ``metrics.csv`` it would really delete.
"""

from __future__ import annotations

import re
import shutil
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from lightning.pytorch.loggers import CSVLogger, Logger

from skeleton_mamba.errors import CheckpointError

__all__ = [
    "BOOKKEEPING",
    "find_last_checkpoint",
    "logger_folders",
    "open_csv_logs",
    "remove_if_empty",
    "resume_in_run_folder",
]

_VERSION = re.compile(r"^version_(\d+)$")
BOOKKEEPING = re.compile(r"^(config\.yaml|hparams\.yaml|metrics\.csv|events\.out\.tfevents\..*)$")


def _get(obj: Any, key: str, default: Any = None) -> Any:
    if isinstance(obj, dict):
        return obj.get(key, default)
    return getattr(obj, key, default)


def _logger_entries(trainer_cfg: Any) -> list[Any]:
    loggers = _get(trainer_cfg, "logger")
    if loggers is None or loggers is True:
        return [None]  # Lightning's default TensorBoardLogger
    if loggers is False:
        return []
    return list(loggers) if isinstance(loggers, (list, tuple)) else [loggers]


def logger_folders(trainer_cfg: Any) -> list[tuple[Path, Any]]:
    """``(save_dir/name, init_args)`` of each configured logger with a ``version_N`` layout."""
    root = Path(_get(trainer_cfg, "default_root_dir") or ".")
    folders = []
    for entry in _logger_entries(trainer_cfg):
        if entry is None:
            folders.append((root / "lightning_logs", None))
            continue
        args = _get(entry, "init_args")
        save_dir, name = _get(args, "save_dir"), _get(args, "name")
        if save_dir is not None and name:
            folders.append((Path(save_dir) / str(name), args))
    return folders


def _versions(folder: Path) -> list[tuple[int, Path]]:
    if not folder.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in folder.iterdir() if p.is_dir() and (m := _VERSION.match(p.name))]
    return sorted(found, reverse=True)


def find_last_checkpoint(trainer_cfg: Any) -> Path:
    """The checkpoint ``--ckpt_path last`` names (module docstring); raises :class:`CheckpointError`."""
    folders = [folder for folder, _ in logger_folders(trainer_cfg)]
    for folder in dict.fromkeys(folders):
        for _, version in _versions(folder):
            checkpoints = list((version / "checkpoints").glob("*.ckpt"))
            if checkpoints:
                last = version / "checkpoints" / "last.ckpt"
                return last if last.is_file() else max(checkpoints, key=lambda p: p.stat().st_mtime)
    where = (
        ", ".join(f"{f}/version_*/checkpoints/" for f in dict.fromkeys(folders))
        or "(the recipe has no logger)"
    )
    raise CheckpointError(
        f"--ckpt_path last: no checkpoint of an earlier run of this recipe in {where}; "
        "drop --ckpt_path to start a new run, or pass a checkpoint file"
    )


def resume_in_run_folder(trainer_cfg: Any, checkpoint: Path) -> int | None:
    """Point the loggers at the run folder holding ``checkpoint``; returns its version (``None``: elsewhere).

    Applies when ``checkpoint`` lies in ``<save_dir>/<name>/version_N/checkpoints/`` of a configured logger.
    """
    checkpoint = checkpoint.resolve()
    run = checkpoint.parent.parent
    match = _VERSION.match(run.name)
    if checkpoint.parent.name != "checkpoints" or match is None:
        return None
    targets = [args for folder, args in logger_folders(trainer_cfg) if folder.resolve() == run.parent]
    if not targets or any(args is None for args in targets):
        return None
    version = int(match.group(1))
    for args in targets:
        if isinstance(args, dict):
            args["version"] = version
        else:
            args.version = version
    metrics = run / "metrics.csv"
    if metrics.is_file():
        k = sum(1 for _ in run.glob("metrics.before_resume_*.csv"))
        metrics.rename(run / f"metrics.before_resume_{k}.csv")
    return version


def remove_if_empty(folder: Path) -> bool:
    """Remove ``folder`` if it holds only logger bookkeeping (:data:`BOOKKEEPING`); returns whether it did."""
    if not folder.is_dir():
        return False
    for path in folder.rglob("*"):
        if path.is_file() and (path.parent != folder or not BOOKKEEPING.match(path.name)):
            return False
    shutil.rmtree(folder)
    return True


def open_csv_logs(loggers: Iterable[Logger]) -> None:
    """Create every CSV logger's writer now (its versions already fixed), before any other logger writes.

    Its "exists and is not empty ... will be deleted" warning is kept only when the folder holds a
    ``metrics.csv`` (the one file it deletes): a resumed run's was renamed by :func:`resume_in_run_folder`.
    """
    for logger in loggers:
        if not isinstance(logger, CSVLogger):
            continue
        with warnings.catch_warnings():
            if not (Path(logger.log_dir) / "metrics.csv").is_file():
                warnings.filterwarnings(
                    "ignore", message="Experiment logs directory .* exists and is not empty"
                )
            _ = logger.experiment
