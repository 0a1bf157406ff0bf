"""Safe checkpoint loading: nothing in a checkpoint file runs code.

A PyTorch checkpoint is a pickle; a plain ``torch.load`` (or Lightning's remote load, which defaults
to ``weights_only=False``) runs whatever callable the file names. Every checkpoint the project reads
goes through :func:`load_checkpoint`:

1. the path must be a local file: URLs (``http://``, ``s3://``, any ``scheme://``) are refused, since a
   remote file is only as trustworthy as the server; download it and check it, then pass the file;
2. the file is read with ``torch.load(weights_only=True)``: tensors, numbers, strings and containers
   only; any other global makes the load fail before it is called;
3. every class path stored in the hyper-parameters (``_class_path``, nested ``class_path`` entries,
   Lightning's ``_instantiator``) must name a module of the project (``skeleton_mamba.*``) or one of
   the library classes recipes use (:data:`TRUSTED_CLASS_PREFIXES`), checked as text before anything
   is imported.

:func:`load_module` builds a LightningModule from a checked checkpoint (``sm dance``, ``sm generate``);
the Lightning CLI checks ``--ckpt_path`` the same way before Lightning reads it, and passes
``weights_only=True`` to Lightning's own load.
"""

from __future__ import annotations

import io
import pickle
import re
import warnings
from collections.abc import Iterator
from os import PathLike
from pathlib import Path
from typing import Any, TypeVar

import torch

from skeleton_mamba.tasks.motion.errors import CheckpointError, RandomWeightsWarning

__all__ = [
    "TRUSTED_CLASS_PREFIXES",
    "check_checkpoint_path",
    "check_class_paths",
    "check_finite_state",
    "load_checkpoint",
    "load_module",
    "load_module_and_checkpoint",
]

# Module prefixes a class path in a checkpoint may name. Short names without a dot
# (``ActionRecognitionModule``) resolve only among classes already imported, so they import nothing.
TRUSTED_CLASS_PREFIXES: tuple[str, ...] = (
    "skeleton_mamba.",
    "lightning.pytorch.",
    "torch.optim.",
    "torch.nn.",
    "torchmetrics.",
)
_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
_DOTTED_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
_CLASS_KEYS = ("class_path", "_class_path", "_instantiator")

ModuleT = TypeVar("ModuleT")


def check_checkpoint_path(path: str | PathLike[str]) -> Path:
    """``path`` as a local checkpoint file; raises :class:`CheckpointError` / :class:`OSError` otherwise."""
    text = str(path)
    if _URL.match(text):
        raise CheckpointError(
            f"{text}: remote checkpoints are refused (a downloaded pickle may run code); download the file, "
            "then pass its local path (it is loaded with weights_only=True)"
        )
    p = Path(text).expanduser()
    if p.is_dir():
        raise IsADirectoryError(21, "Is a directory", text)
    if not p.is_file():
        raise FileNotFoundError(2, "No such checkpoint file", text)
    return p


def _class_paths(value: Any, where: str = "hyper_parameters") -> Iterator[tuple[str, Any]]:
    if isinstance(value, dict):
        for key, item in value.items():
            if key in _CLASS_KEYS:
                yield f"{where}.{key}", item
            yield from _class_paths(item, f"{where}.{key}")
    elif isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            yield from _class_paths(item, f"{where}[{i}]")


def check_class_paths(hparams: Any, source: str) -> None:
    """Refuse a class path in ``hparams`` outside :data:`TRUSTED_CLASS_PREFIXES` (nothing is imported).

    Raises:
        CheckpointError: naming ``source``, the key and the refused class path.
    """
    for where, value in _class_paths(hparams):
        trusted = (
            isinstance(value, str)
            and _DOTTED_NAME.match(value) is not None
            and ("." not in value or value.startswith(TRUSTED_CLASS_PREFIXES))
        )
        if not trusted:
            raise CheckpointError(
                f"{source}: {where} names {value!r}, outside the project's modules "
                f"({', '.join(p.rstrip('.') for p in TRUSTED_CLASS_PREFIXES)}); refusing to import it"
            )


def _torch_load(data: bytes | Path, source: str, map_location: Any) -> Any:
    try:
        return torch.load(
            io.BytesIO(data) if isinstance(data, bytes) else data,
            map_location=map_location,
            weights_only=True,
        )
    except pickle.UnpicklingError as err:
        first = str(err).strip().splitlines()
        detail = next(
            (line for line in first if "GLOBAL" in line or "Unsupported" in line), first[0] if first else ""
        )
        raise CheckpointError(
            f"{source}: not a plain-data checkpoint, refused (weights_only load: {detail.strip()})"
        ) from None
    except (RuntimeError, EOFError, ValueError, KeyError) as err:
        raise CheckpointError(
            f"{source}: not a readable PyTorch checkpoint ({type(err).__name__}: {err})"
        ) from None


def load_checkpoint(path: str | PathLike[str], map_location: Any = "cpu") -> dict:
    """A checkpoint as a dict, checked as the module docstring says (path, ``weights_only``, class paths).

    Raises:
        CheckpointError: a URL, a pickle that names code, an unreadable file or a foreign class path.
        FileNotFoundError / IsADirectoryError: the path is missing or a folder.
    """
    p = check_checkpoint_path(path)
    checkpoint = _torch_load(p, str(p), map_location)
    if not isinstance(checkpoint, dict):
        raise CheckpointError(f"{p}: a checkpoint holds a dict, got {type(checkpoint).__name__}")
    check_class_paths(checkpoint.get("hyper_parameters", {}), str(p))
    return checkpoint


def load_module(cls: type[ModuleT], path: str | PathLike[str], map_location: Any = "cpu") -> ModuleT:
    """``cls.load_from_checkpoint`` on a checked checkpoint: read once, checked, then built ``weights_only``.

    Raises:
        CheckpointError: as :func:`load_checkpoint`, or when the file holds another module class.
    """
    return load_module_and_checkpoint(cls, path, map_location)[0]


def load_module_and_checkpoint(
    cls: type[ModuleT], path: str | PathLike[str], map_location: Any = "cpu"
) -> tuple[ModuleT, dict]:
    """:func:`load_module`, and the checkpoint's dict as read (e.g. its ``datamodule_hyper_parameters``),
    from one read of the file."""
    p = check_checkpoint_path(path)
    data = p.read_bytes()
    checkpoint = _torch_load(data, str(p), map_location)
    if not isinstance(checkpoint, dict) or "state_dict" not in checkpoint:
        raise CheckpointError(f"{p}: not a Lightning checkpoint (no 'state_dict')")
    hparams = checkpoint.get("hyper_parameters", {})
    check_class_paths(hparams, str(p))
    stored = hparams.get("_class_path") if isinstance(hparams, dict) else None
    if isinstance(stored, str) and stored.rsplit(".", 1)[-1] != cls.__name__:
        raise CheckpointError(f"{p}: holds a {stored}, not a {cls.__name__}")
    try:
        with warnings.catch_warnings():  # the checkpoint's weights replace any random initialisation
            warnings.simplefilter("ignore", RandomWeightsWarning)
            module = cls.load_from_checkpoint(io.BytesIO(data), map_location=map_location, weights_only=True)  # type: ignore[attr-defined]
    except (KeyError, TypeError, RuntimeError) as err:
        raise CheckpointError(f"{p}: does not fit {cls.__name__} ({type(err).__name__}: {err})") from err
    check_finite_state(module, str(p))
    return module, checkpoint


def check_finite_state(module: torch.nn.Module, source: str) -> None:
    """Raise :class:`CheckpointError` naming the first parameter or buffer of ``module`` holding NaN or Inf
    (such a model only produces non-finite output, which no command writes)."""
    for name, tensor in (*module.named_parameters(), *module.named_buffers()):
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            bad = int((~torch.isfinite(tensor)).sum())
            raise CheckpointError(
                f"{source}: weights are not finite ({name}: {bad} of {tensor.numel()} values NaN or Inf)"
            )
