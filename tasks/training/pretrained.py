"""Commands' models from a Lightning checkpoint, a ``from_pretrained`` folder or a Hub id.

A folder written by ``sm export-pretrained`` (:mod:`.export_pretrained`) is a network's ``from_pretrained``
folder (:mod:`skeleton_mamba.pretrained.mixin`: ``config.json``, ``model.safetensors``, ``README.md``) whose
``config.json`` also records the Lightning module it came from (``"module"``: class path, hyper-parameters,
the data module's hyper-parameters, where the network sits in the module), and a fourth file,
``module.safetensors``, with the module's other tensors (a head estimator, the EMA's counter). From those
:func:`load_module_and_checkpoint_from` rebuilds the module, through the project's one checkpoint loader
(:func:`~skeleton_mamba.tasks.training.checkpoints.load_module_and_checkpoint`: class paths checked, weights
only, finite weights), so ``sm dance`` / ``sm generate`` / ``sm stream`` / ``sm predict`` give the same
output from the folder as from the checkpoint. Every tensor comes from safetensors: nothing is unpickled.

Sources: a path to a file is a checkpoint; a folder or a Hub id (``org/name``, resolved through the Hugging
Face cache, offline with ``HF_HUB_OFFLINE=1``) is a pretrained folder.
"""

from __future__ import annotations

import atexit
import dataclasses
import importlib
import os
import re
import shutil
import tempfile
import typing
from pathlib import Path
from typing import Any, TypeVar

import torch
from lightning.pytorch import LightningModule
from safetensors import SafetensorError
from safetensors.torch import load_file

from skeleton_mamba.errors import CheckpointError
from skeleton_mamba.pretrained.checks import check_sizes, read_safetensors_header
from skeleton_mamba.pretrained.mixin import (
    CONFIG_NAME,
    WEIGHTS_NAME,
    PretrainedError,
    decode_value,
    encode_value,
    read_pretrained_config,
    resolve_pretrained,
)
from skeleton_mamba.tasks.training.checkpoints import (
    check_checkpoint_path,
    check_class_paths,
    check_finite_tensors,
    load_module_and_checkpoint,
)
from skeleton_mamba.tasks.training.registry import task_packages

__all__ = [
    "MODULE_WEIGHTS_NAME",
    "check_model_source",
    "checkpoint_file_from",
    "import_project_class",
    "is_checkpoint_source",
    "load_module_and_checkpoint_from",
    "load_module_from",
    "load_network",
    "module_record",
    "plain_hparams",
]

MODULE_WEIGHTS_NAME = "module.safetensors"
_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
_CHECKPOINT_SUFFIXES = (".ckpt", ".pt", ".pth")

ModuleT = TypeVar("ModuleT", bound=LightningModule)


def is_checkpoint_source(source: str | os.PathLike[str]) -> bool:
    """True when ``source`` names a checkpoint file (a URL, a file, a ``.ckpt`` / ``.pt`` name), False for a
    folder or a Hub id."""
    text = os.fspath(source)
    path = Path(text).expanduser()
    if _URL.match(text) or path.is_file() or text.endswith(_CHECKPOINT_SUFFIXES):
        return True
    return not path.is_dir() and not re.match(
        r"^[A-Za-z0-9][A-Za-z0-9_.-]*/[A-Za-z0-9][A-Za-z0-9_.-]*$", text
    )


def check_model_source(source: str | os.PathLike[str]) -> None:
    """Refuse before any work a URL, a missing checkpoint, or a folder without ``config.json``.

    A Hub id is checked when it is resolved (:func:`load_module_and_checkpoint_from`).
    """
    if is_checkpoint_source(source):
        check_checkpoint_path(source)
        return
    path = Path(os.fspath(source)).expanduser()
    if path.is_dir() and not (path / CONFIG_NAME).is_file():
        raise CheckpointError(f"{source}: a folder without {CONFIG_NAME} (not a from_pretrained folder)")


def _resolve(source: str | os.PathLike[str]) -> tuple[Path, dict]:
    try:
        folder = resolve_pretrained(source)
        return folder, read_pretrained_config(folder)
    except PretrainedError as err:
        raise CheckpointError(str(err)) from err


def import_project_class(path: str, source: str, base: type | None = None) -> type:
    """The class a config names: checked as text (the project's modules and the registered tasks' packages
    only, :mod:`.registry`) before its module is imported, then checked to be a class (a subclass of ``base``
    when given)."""
    check_class_paths({"class_path": path}, source)
    project = ("skeleton_mamba.", *(f"{package}." for package in task_packages()))
    if not path.startswith(project) or "." not in path:
        raise CheckpointError(f"{source}: names {path!r}, not a class of the project")
    module_name, _, name = path.rpartition(".")
    try:
        cls = getattr(importlib.import_module(module_name), name)
    except (ImportError, AttributeError):
        raise CheckpointError(f"{source}: names an unknown class {path!r}") from None
    if not isinstance(cls, type) or (base is not None and not issubclass(cls, base)):
        kind = base.__name__ if base is not None else "class"
        raise CheckpointError(f"{source}: names {path!r}, which is not a {kind}")
    return cls


def _network_class(config: dict, where: str) -> type:
    """The network class ``config.json`` names, one with ``from_pretrained``."""
    cls = import_project_class(config["class"], where)
    if not hasattr(cls, "check_pretrained_folder") or not hasattr(cls, "load_pretrained_weights"):
        raise CheckpointError(f"{where}: names {config['class']!r}, not a network with from_pretrained")
    return cls


def load_network(source: str | os.PathLike[str], device: str | torch.device = "cpu") -> torch.nn.Module:
    """The network in a ``from_pretrained`` folder or Hub id, whatever its class (the backbone or a task's),
    checked before anything is allocated (``from_pretrained``'s checks).

    Raises:
        CheckpointError: not such a folder, an unknown class, config or tensors that do not fit.
    """
    folder, config = _resolve(source)
    cls = _network_class(config, str(folder / CONFIG_NAME))
    try:
        return cls.from_folder(folder, device)
    except PretrainedError as err:
        raise CheckpointError(str(err)) from err


def _plain(value: Any) -> Any:
    """Config dataclasses as dicts: checkpoint hyper-parameters hold plain data only (``weights_only``)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, tuple):
        return tuple(_plain(v) for v in value)
    return value


def plain_hparams(cls: type, stored: dict, where: str) -> dict:
    """Hyper-parameters read from JSON with their types back (tuples, non-finite floats), from the
    annotations of ``cls.__init__``; a value that fits no annotation stays as stored."""
    try:
        hints = typing.get_type_hints(cls.__init__)
    except (NameError, TypeError):
        hints = {}
    out = {}
    for name, value in stored.items():
        try:
            out[name] = _plain(decode_value(value, hints.get(name, Any), f"{where}: {name}"))
        except PretrainedError:
            out[name] = value
    return out


def module_record(module: LightningModule, checkpoint: dict, network: str) -> dict:
    """The ``"module"`` entry of an exported ``config.json``: class path, hyper-parameters (JSON), the data
    module's hyper-parameters, and the module attribute path of the exported network."""
    hparams = dict(checkpoint.get("hyper_parameters") or {})
    cls = type(module)
    hparams.setdefault("_class_path", f"{cls.__module__}.{cls.__qualname__}")
    record = {
        "class_path": f"{cls.__module__}.{cls.__qualname__}",
        "network": network,
        "hparams": encode_value(hparams, "hyper_parameters"),
        "datamodule_hyper_parameters": encode_value(
            dict(checkpoint.get("datamodule_hyper_parameters") or {}), "datamodule_hyper_parameters"
        ),
    }
    for key in ("epoch", "global_step"):
        if isinstance(checkpoint.get(key), int):
            record[key] = checkpoint[key]
    if isinstance(checkpoint.get("pytorch-lightning_version"), str):
        record["lightning_version"] = checkpoint["pytorch-lightning_version"]
    return record


def load_module_and_checkpoint_from(
    cls: type[ModuleT], source: str | os.PathLike[str], map_location: Any = "cpu"
) -> tuple[ModuleT, dict]:
    """``cls`` and its checkpoint dict from a checkpoint file, or from an exported folder / Hub id.

    Raises:
        CheckpointError: as :func:`~skeleton_mamba.tasks.training.checkpoints.load_module_and_checkpoint`;
            for a folder also: not exported from a Lightning module, another module class, tensors that
            do not fit.
    """
    if is_checkpoint_source(source):
        return load_module_and_checkpoint(cls, source, map_location)
    folder, checkpoint = _folder_checkpoint(source, cls)
    return load_module_folder(cls, folder, checkpoint, map_location)


def _folder_checkpoint(source: str | os.PathLike[str], cls: type | None = None) -> tuple[Path, dict]:
    """The folder of ``source`` and the Lightning checkpoint dict its files describe (``cls``: the module
    class it must hold)."""
    folder, config = _resolve(source)
    where = str(folder / CONFIG_NAME)
    record = config.get("module")
    if not isinstance(record, dict) or not isinstance(record.get("network"), str):
        raise CheckpointError(
            f"{where}: a bare {config['class'].rsplit('.', 1)[-1]} with no Lightning module recorded "
            f"(load it with from_pretrained; sm export-pretrained writes folders the commands read)"
        )
    stored = str(record.get("class_path", ""))
    if cls is not None and stored.rsplit(".", 1)[-1] != cls.__name__:
        raise CheckpointError(f"{where}: holds a {stored}, not a {cls.__name__}")
    check_class_paths(record, where)  # nested class paths too (an optimizer's), before anything is imported
    module_cls = cls or import_project_class(stored, where, LightningModule)
    network_cls = _network_class(config, where)
    try:  # the network's sizes, its values and its weights' header, before any tensor is read
        network_cls.check_pretrained_folder(folder, config)
        check_sizes(record.get("hparams") or {}, f"{where}: module hparams", CheckpointError)
        extra_path = folder / MODULE_WEIGHTS_NAME
        if extra_path.exists():
            read_safetensors_header(extra_path, CheckpointError)
        weights = load_file(str(folder / WEIGHTS_NAME))
        extra = load_file(str(extra_path)) if extra_path.exists() else {}
        check_finite_tensors(weights, str(folder / WEIGHTS_NAME))
        check_finite_tensors(extra, str(extra_path))
        network = {f"{record['network']}.{k}": v for k, v in weights.items()}
    except PretrainedError as err:
        raise CheckpointError(str(err)) from err
    except (SafetensorError, OSError) as err:
        raise CheckpointError(f"{folder}: unreadable weights ({err})") from None
    checkpoint = {
        "state_dict": {**extra, **network},
        "hyper_parameters": plain_hparams(module_cls, dict(record.get("hparams") or {}), where),
        "datamodule_hyper_parameters": dict(record.get("datamodule_hyper_parameters") or {}),
        "pytorch-lightning_version": str(record.get("lightning_version", "2.5.2")),
    }
    for key in ("epoch", "global_step"):
        if key in record:
            checkpoint[key] = record[key]
    return folder, checkpoint


def load_module_folder(
    cls: type[ModuleT], folder: Path, checkpoint: dict, map_location: Any = "cpu"
) -> tuple[ModuleT, dict]:
    """``cls`` from the checkpoint dict of an exported ``folder`` (:func:`_folder_checkpoint`)."""
    # the one loader (class paths, weights_only, finite weights), on the checkpoint the folder describes
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "from_pretrained.ckpt"
        torch.save(checkpoint, path)
        try:
            module, loaded = load_module_and_checkpoint(cls, path, map_location)
        except CheckpointError as err:
            raise CheckpointError(str(err).replace(str(path), str(folder))) from err
    return module, loaded


def checkpoint_file_from(
    source: str | os.PathLike[str], directory: str | os.PathLike[str] | None = None
) -> Path:
    """The Lightning checkpoint an exported folder / Hub id describes, written into ``directory`` (for
    ``sm test|predict --ckpt_path FOLDER_OR_ID``, which Lightning reads as a file; ``None``: a temporary
    folder removed when the process exits)."""
    folder, checkpoint = _folder_checkpoint(source)
    if directory is None:
        directory = tempfile.mkdtemp(prefix="sm-pretrained-")
        atexit.register(shutil.rmtree, directory, True)
    path = Path(directory) / f"{folder.name or 'pretrained'}.ckpt"
    torch.save(checkpoint, path)
    return path


def load_module_from(
    cls: type[ModuleT], source: str | os.PathLike[str], map_location: Any = "cpu"
) -> ModuleT:
    """:func:`load_module_and_checkpoint_from`, the module only."""
    return load_module_and_checkpoint_from(cls, source, map_location)[0]
