"""Safe checkpoint loading: nothing in a checkpoint file runs code.

A PyTorch checkpoint is a pickle; a plain ``torch.load`` (or Lightning's remote load, which defaults
to ``weights_only=False``) runs whatever callable the file names. Every checkpoint the project reads
goes through :func:`load_checkpoint`:

1. the path must be a local file: URLs (``http://``, ``s3://``, any ``scheme://``) are refused, since a
   remote file is only as trustworthy as the server; download it and check it, then pass the file;
2. the file is read with ``torch.load(weights_only=True)``: tensors, numbers, strings and containers
   only; any other global makes the load fail before it is called;
3. its structure is checked before anything walks it recursively: containers nest at most
   :data:`MAX_NESTING` levels, ``state_dict`` maps names to tensors, the hyper-parameters are a mapping;
4. every class path stored in the hyper-parameters (``_class_path``, nested ``class_path`` entries,
   Lightning's ``_instantiator``) must name a module of the project (``skeleton_mamba.*``) or one of
   the library classes recipes use (:data:`TRUSTED_CLASS_PREFIXES`), or of a registered task's package
   (:func:`trusted_class_prefixes`), checked as text before anything is imported.

:func:`load_module` builds a LightningModule from a checked checkpoint (``sm dance``, ``sm generate``,
``sm stream``, ``sm export-pretrained``, ``sm export-onnx``). Before any weight is copied it checks the
checkpoint against the task: the class it names is the one the command runs (else the message names the
task the file holds), every tensor is finite, and the tensors' names and shapes are those of the module
built from the checkpoint's hyper-parameters (:func:`check_state_fits`: missing and unexpected names,
the first shape that differs, both shapes). The Lightning CLI checks ``--ckpt_path`` the same way before
Lightning reads it, checks its tensors against the instantiated model, and passes ``weights_only=True``
to Lightning's own load. :class:`CheckedCheckpointIO` is the trainer's checkpoint reader and writer:
reads through :func:`load_checkpoint`, writes through a temporary file in the checkpoint's own folder.

Data paths (:data:`DATA_PATH_KEYS` of ``datamodule_hyper_parameters``) given relative to the folder ``sm fit``
ran in are stored relative to the checkpoint file (:func:`store_paths_relative`; the keys listed under
:data:`RELATIVE_PATHS_KEY`), and every read resolves them against the file's folder
(:func:`resolve_stored_paths`), so a run folder moved or copied with its data still finds it. An older
checkpoint's working-folder-relative path is looked up from the checkpoint's folders upwards when the
current folder does not hold it.
"""

from __future__ import annotations

import argparse
import contextlib
import inspect
import io
import os
import pickle
import re
import warnings
from collections.abc import Callable, Iterator, Mapping
from os import PathLike
from pathlib import Path
from typing import Any, TypeVar

import torch
from lightning.pytorch.plugins.io import TorchCheckpointIO

from skeleton_mamba.errors import CheckpointError, RandomWeightsWarning
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.pretrained.checks import MAX_PARAMETERS, check_finite_weights, check_sizes, dtype_fits
from skeleton_mamba.tasks.training.registry import task_of_class_path, task_packages

__all__ = [
    "DATA_PATH_KEYS",
    "MAX_NESTING",
    "RELATIVE_PATHS_KEY",
    "TRUSTED_CLASS_PREFIXES",
    "CheckedCheckpointIO",
    "check_checkpoint_path",
    "check_checkpoint_structure",
    "check_class_paths",
    "check_finite_state",
    "check_finite_tensors",
    "check_settings_known",
    "check_state_fits",
    "checked_state_shapes",
    "trusted_class_prefixes",
    "load_checkpoint",
    "load_module",
    "load_module_and_checkpoint",
    "resolve_stored_paths",
    "state_shapes",
    "store_paths_relative",
    "use_checked_checkpoint_io",
]

# Deepest nesting of containers a checkpoint may hold (a Lightning checkpoint with optimizer states
# nests about 6 deep); checked without recursion before anything recursive (the class-path check,
# Lightning's and jsonargparse's hyper-parameter handling) walks it.
MAX_NESTING = 100
# Entries of a Lightning checkpoint that hold plain-data mappings (when present).
_MAPPING_KEYS = ("hyper_parameters", "datamodule_hyper_parameters")
# Entries Lightning does not need to build a module (:func:`load_module_and_checkpoint`).
_TRAINING_STATE_KEYS = ("state_dict", "optimizer_states", "lr_schedulers", "callbacks", "loops")

# Module prefixes a class path in a checkpoint may name. Short names without a dot
# (``ActionRecognitionModule``) resolve only among classes already imported, so they import nothing.
TRUSTED_CLASS_PREFIXES: tuple[str, ...] = (
    "skeleton_mamba.",
    "lightning.pytorch.",
    "torch.optim.",
    "torch.nn.",
    "torchmetrics.",
)


def trusted_class_prefixes() -> tuple[str, ...]:
    """:data:`TRUSTED_CLASS_PREFIXES` and the package of every registered task (:mod:`.registry`): a task in
    another distribution is trusted like the project's own modules, since installing it registered it."""
    extra = tuple(f"{package}." for package in task_packages())
    return (*TRUSTED_CLASS_PREFIXES, *(p for p in extra if not p.startswith(TRUSTED_CLASS_PREFIXES)))


_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
_DOTTED_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
_CLASS_KEYS = ("class_path", "_class_path", "_instantiator")

ModuleT = TypeVar("ModuleT")

# The data module arguments that name files or folders.
DATA_PATH_KEYS = ("root", "ann_file", "music_dir", "music_cache_dir", "predict_seed", "predict_music")
RELATIVE_PATHS_KEY = "datamodule_paths_relative_to_checkpoint"


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
    """Refuse a class path in ``hparams`` outside :func:`trusted_class_prefixes` (nothing is imported).

    Raises:
        CheckpointError: naming ``source``, the key and the refused class path.
    """
    prefixes = trusted_class_prefixes()
    for where, value in _class_paths(hparams):
        trusted = (
            isinstance(value, str)
            and _DOTTED_NAME.match(value) is not None
            and ("." not in value or value.startswith(prefixes))
        )
        if not trusted:
            raise CheckpointError(
                f"{source}: {where} names {value!r}, outside the project's modules "
                f"({', '.join(p.rstrip('.') for p in prefixes)}); refusing to import it"
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
    except OSError as err:
        if err.filename is not None:  # the file itself (permissions, a read error): its own one-line message
            raise
        raise CheckpointError(  # torch's zip reader on a truncated file: errno 22, "Invalid argument"
            f"{source}: not a readable PyTorch checkpoint (truncated or damaged: {err.strerror or err})"
        ) from None
    except Exception as err:  # any failure to parse untrusted bytes (IndexError, struct.error, ...)
        first = str(err).strip().splitlines()
        raise CheckpointError(
            f"{source}: not a readable PyTorch checkpoint ({type(err).__name__}: {first[0] if first else ''})"
        ) from None


def _too_deep(value: Any, limit: int) -> str | None:
    """The top-level key (or ``"the checkpoint"``) under which ``value`` nests deeper than ``limit``
    containers; ``None`` when it does not. Iterative: no recursion, whatever the depth."""
    stack: list[tuple[Any, int, str]] = [(value, 0, "the checkpoint")]
    while stack:
        item, depth, top = stack.pop()
        if isinstance(item, Mapping):
            children: Any = item.values()
        elif isinstance(item, (list, tuple, set, frozenset)):
            children = item
        else:
            continue
        if depth >= limit:
            return top
        if depth == 0 and isinstance(item, Mapping):
            stack.extend((child, 1, repr(key)) for key, child in item.items())
        else:
            stack.extend((child, depth + 1, top) for child in children)
    return None


def _expanded_tensor(value: Any) -> tuple[str, torch.Tensor] | None:
    """The first tensor under ``value`` (walked without recursion) with more elements than its storage
    holds (a broadcast ``expand``: a few bytes in the file, any size once touched), and where it is."""
    stack: list[tuple[Any, str]] = [(value, "the checkpoint")]
    while stack:
        item, where = stack.pop()
        if isinstance(item, torch.Tensor):
            stored = item.untyped_storage().nbytes() // max(item.element_size(), 1)
            if item.numel() > max(stored, 0):
                return where, item
        elif isinstance(item, Mapping):
            stack.extend((child, f"{where}[{key!r}]") for key, child in item.items())
        elif isinstance(item, (list, tuple)):
            stack.extend((child, f"{where}[{i}]") for i, child in enumerate(item))
    return None


def check_checkpoint_structure(checkpoint: Any, source: str) -> None:
    """Refuse a checkpoint whose structure no loader may walk: not a dict, containers nested deeper than
    :data:`MAX_NESTING`, a ``state_dict`` that is not a mapping of names to tensors, hyper-parameters that
    are not a mapping, a tensor with more elements than its storage holds (a lazily expanded view).

    Raises:
        CheckpointError: naming ``source`` and the entry at fault.
    """
    if not isinstance(checkpoint, dict):
        raise CheckpointError(f"{source}: a checkpoint holds a dict, got {type(checkpoint).__name__}")
    deep = _too_deep(checkpoint, MAX_NESTING)
    if deep is not None:
        raise CheckpointError(
            f"{source}: {deep} nests containers deeper than {MAX_NESTING} levels; refused (a checkpoint's "
            "hyper-parameters nest a few levels)"
        )
    if "state_dict" in checkpoint:
        state = checkpoint["state_dict"]
        if not isinstance(state, Mapping):
            raise CheckpointError(
                f"{source}: state_dict is a {type(state).__name__}, not a mapping of tensor names to tensors"
            )
        for key, value in state.items():
            if not isinstance(key, str) or not isinstance(value, torch.Tensor):
                raise CheckpointError(
                    f"{source}: state_dict[{key!r}] is a {type(value).__name__}"
                    f"{'' if isinstance(key, str) else f' under a {type(key).__name__} key'}, "
                    "not a tensor under a name"
                )
    expanded = _expanded_tensor(checkpoint)
    if expanded is not None:
        where, tensor = expanded
        raise CheckpointError(
            f"{source}: {where} is a tensor of {tensor.numel():,} elements over a storage of "
            f"{tensor.untyped_storage().nbytes():,} bytes (an expanded view); refused"
        )
    for key in _MAPPING_KEYS:
        value = checkpoint.get(key)
        if value is not None and not isinstance(value, Mapping):
            raise CheckpointError(
                f"{source}: {key} is a {type(value).__name__}, not a mapping of argument names to values"
            )
        if isinstance(value, Mapping) and not all(isinstance(name, str) for name in value):
            bad = next(name for name in value if not isinstance(name, str))
            raise CheckpointError(
                f"{source}: {key} has a {type(bad).__name__} key {bad!r}, not an argument name"
            )


def load_checkpoint(path: str | PathLike[str], map_location: Any = "cpu") -> dict:
    """A checkpoint as a dict, checked as the module docstring says (path, ``weights_only``, structure,
    class paths).

    Raises:
        CheckpointError: a URL, a pickle that names code, an unreadable file, a structure no loader may
            walk (:func:`check_checkpoint_structure`) or a foreign class path.
        FileNotFoundError / IsADirectoryError: the path is missing or a folder.
    """
    p = check_checkpoint_path(path)
    return resolve_stored_paths(_checked(_torch_load(p, str(p), map_location), str(p)), p)


def _checked(checkpoint: Any, source: str) -> dict:
    check_checkpoint_structure(checkpoint, source)
    check_class_paths(checkpoint.get("hyper_parameters", {}), source)
    return checkpoint


def store_paths_relative(checkpoint: dict, path: str | PathLike[str]) -> dict:
    """``checkpoint`` with each relative data path (:data:`DATA_PATH_KEYS`, relative to the working folder,
    existing) rewritten relative to the folder of ``path`` (where it is being saved), the keys listed under
    :data:`RELATIVE_PATHS_KEY`; absolute paths stay as they are. The input is not changed."""
    hparams = checkpoint.get("datamodule_hyper_parameters")
    if not isinstance(hparams, Mapping):
        return checkpoint
    folder = Path(path).absolute().parent
    stored, keys = dict(hparams), []
    for key in DATA_PATH_KEYS:
        value = hparams.get(key)
        if isinstance(value, str) and value and not _URL.match(value) and not Path(value).is_absolute():
            if Path(value).exists():
                stored[key] = Path(os.path.relpath(Path(value).absolute(), folder)).as_posix()
                keys.append(key)
    if not keys:
        return checkpoint
    return {**checkpoint, "datamodule_hyper_parameters": stored, RELATIVE_PATHS_KEY: keys}


def resolve_stored_paths(checkpoint: dict, path: Path) -> dict:
    """The data paths of a checkpoint read from ``path`` as usable paths (module docstring), in place."""
    hparams = checkpoint.get("datamodule_hyper_parameters")
    if not isinstance(hparams, dict):
        return checkpoint
    folder = Path(path).absolute().parent
    keys = checkpoint.get(RELATIVE_PATHS_KEY)
    if isinstance(keys, list):
        for key in keys:
            if isinstance(key, str) and isinstance(hparams.get(key), str):
                hparams[key] = os.path.normpath(folder / hparams[key])
        return checkpoint
    for key in DATA_PATH_KEYS:  # an older checkpoint: relative to the folder sm fit ran in
        value = hparams.get(key)
        if not isinstance(value, str) or not value or Path(value).is_absolute() or Path(value).exists():
            continue
        found = next((f / value for f in folder.parents if (f / value).exists()), None)
        if found is not None:
            hparams[key] = os.path.normpath(found)
    return checkpoint


def _task_of(class_path: str) -> str:
    """``"EgoDance"`` for ``skeleton_mamba.tasks.egodance.module.EgoDanceModule``: the title of the registered
    task whose package holds the class (:mod:`.registry`); the class name outside every task."""
    task = task_of_class_path(class_path)
    return task.title if task is not None else class_path.split(".")[-1]


def _a(word: str) -> str:
    return f"{'an' if word[:1].lower() in 'aeiou' else 'a'} {word}"


def state_shapes(state: Mapping[str, torch.Tensor] | torch.nn.Module) -> dict[str, tuple[int, ...]]:
    """The name -> shape table of a state dict (or of a module's ``state_dict()``)."""
    if isinstance(state, torch.nn.Module):
        state = state.state_dict()
    return {name: tuple(tensor.shape) for name, tensor in state.items()}


def check_state_fits(
    module: torch.nn.Module, found: Mapping[str, tuple[int, ...]], source: str, built_from: str = ""
) -> None:
    """Refuse a checkpoint whose tensors (``found``: name -> shape) are not those of ``module``.

    Checked before ``load_state_dict``, so the message is one line: how many names are missing and how
    many unexpected (the first of each, in the module's order), else the first tensor whose shape
    differs, with both shapes. ``built_from`` says how the module was built (part of the message).

    Raises:
        CheckpointError: naming ``source``, the module's class and what does not match.
    """
    expected = state_shapes(module)
    what = f"{source}: does not fit {type(module).__name__}{built_from}"
    missing = [name for name in expected if name not in found]
    unexpected = [name for name in found if name not in expected]
    if missing or unexpected:
        parts = []
        if missing:
            parts.append(f"{len(missing)} of its {len(expected)} tensors missing (first: {missing[0]!r})")
        if unexpected:
            parts.append(f"{len(unexpected)} unexpected (first: {unexpected[0]!r})")
        raise CheckpointError(f"{what}: {', '.join(parts)}")
    for name, shape in expected.items():
        if tuple(found[name]) != shape:
            raise CheckpointError(
                f"{what}: {name} has shape {tuple(found[name])} in the checkpoint, {shape} in the model"
            )


def check_settings_known(cls: type, hparams: Mapping[str, Any], source: str) -> None:
    """Refuse hyper-parameters that ``cls.__init__`` does not take (a checkpoint of an earlier version of
    the task, whose settings would otherwise be dropped for the defaults without a word).

    Keys starting with ``_`` (Lightning's ``_class_path``, ``_instantiator``) are not settings; a class
    whose ``__init__`` takes ``**kwargs`` accepts any.

    Raises:
        CheckpointError: naming ``source``, the unknown settings and the class.
    """
    parameters = inspect.signature(cls.__init__).parameters.values()
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return
    names = {p.name for p in parameters}
    unknown = sorted(k for k in hparams if not str(k).startswith("_") and k not in names)
    if unknown:
        more = f" and {len(unknown) - 5} more" if len(unknown) > 5 else ""
        shown = ", ".join(map(str, unknown[:5])) + more
        raise CheckpointError(
            f"{source}: settings {shown} are not {cls.__name__} arguments: the checkpoint was written by "
            "another version of the task (train it again with this version)"
        )


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
    checkpoint = resolve_stored_paths(_checked(_torch_load(p, str(p), map_location), str(p)), p)
    if "state_dict" not in checkpoint:
        raise CheckpointError(f"{p}: not a Lightning checkpoint (no 'state_dict')")
    stored = checkpoint.get("hyper_parameters", {}).get("_class_path")
    if stored is not None and str(stored).rsplit(".", 1)[-1] != cls.__name__:
        raise CheckpointError(
            f"{p}: holds a {stored}, not a {cls.__name__} (this is {_a(_task_of(str(stored)))} checkpoint, "
            f"not {_a(_task_of(f'{cls.__module__}.{cls.__qualname__}'))} one)"
        )
    check_settings_known(cls, checkpoint.get("hyper_parameters", {}), str(p))
    check_sizes(checkpoint.get("hyper_parameters", {}), f"{p}: hyper_parameters", CheckpointError)
    state = checkpoint["state_dict"]
    check_finite_tensors(state, str(p))
    # The module as Lightning builds it from the hyper-parameters (its instantiator, old hparams keys),
    # first on the meta device (shapes, no memory): the tensors are checked against it before the module
    # is built for real, whose memory is then that of the tensors the file holds.
    shell = {k: v for k, v in checkpoint.items() if k not in _TRAINING_STATE_KEYS}
    buffer = io.BytesIO()
    torch.save({**shell, "state_dict": {}}, buffer)
    built = " (as built from the checkpoint's hyper-parameters)" if checkpoint.get("hyper_parameters") else ""
    shape = _build_module(cls, buffer.getvalue(), "meta", p)
    values = sum(t.numel() for t in shape.state_dict().values())
    if values > MAX_PARAMETERS:
        raise CheckpointError(
            f"{p}: its hyper-parameters build a {cls.__name__} of {values:,} values, more than "
            f"{MAX_PARAMETERS:,}"
        )
    check_state_fits(shape, state_shapes(state), str(p), built)
    for name, tensor in shape.state_dict().items():
        if not dtype_fits(state[name].dtype, tensor.dtype):
            raise CheckpointError(
                f"{p}: {name} is stored as {state[name].dtype}, {cls.__name__} holds {tensor.dtype} "
                "(a weight of the wrong type is refused, not cast)"
            )
    module = _build_module(cls, buffer.getvalue(), map_location, p)
    try:
        module.load_state_dict(state, strict=True)
    except RuntimeError as err:  # names and shapes fit; a dtype that does not (complex into real)
        first = str(err).strip().splitlines()
        raise CheckpointError(f"{p}: does not fit {cls.__name__} ({' '.join(first[-1:]).strip()})") from err
    device = next((t.device for t in state.values()), None)
    return (module if device is None else module.to(device)), checkpoint


def _build_module(cls: type[ModuleT], shell: bytes, map_location: Any, path: Path) -> ModuleT:
    """``cls.load_from_checkpoint`` of a checkpoint without tensors (``shell``), with no weights; on the
    ``meta`` device when ``map_location`` is ``"meta"``."""
    meta = map_location == "meta"
    try:
        with warnings.catch_warnings(), torch.device("meta") if meta else contextlib.nullcontext():
            warnings.simplefilter("ignore", RandomWeightsWarning)  # the checkpoint's weights replace them
            for built_empty in (
                "The state dict in .* contains no parameters",
                "Found keys that are in the model",
            ):
                warnings.filterwarnings("ignore", message=built_empty)
            return cls.load_from_checkpoint(  # type: ignore[attr-defined]
                io.BytesIO(shell), map_location=map_location, weights_only=True, strict=False
            )
    except argparse.ArgumentError as err:  # jsonargparse (Lightning's instantiator) refusing a value
        text = " ".join(str(err).split())
        text = text if len(text) <= 300 else text[:297] + "..."
        raise CheckpointError(f"{path}: its hyper-parameters do not fit {cls.__name__} ({text})") from err
    except (KeyError, TypeError, ValueError, RuntimeError, NotImplementedError) as err:
        first = str(err).strip().splitlines()
        raise CheckpointError(
            f"{path}: does not fit {cls.__name__} ({type(err).__name__}: {first[0] if first else ''})"
        ) from err


def checked_state_shapes(checkpoint: dict, source: str) -> dict[str, tuple[int, ...]]:
    """The name -> shape table of a :func:`load_checkpoint` result's ``state_dict``, after checking it is a
    Lightning checkpoint with finite tensors (for ``--ckpt_path``: the table is checked against the
    instantiated model with :func:`check_state_fits` before the trainer loads the weights).

    Raises:
        CheckpointError: no ``state_dict``, or a tensor holding NaN or Inf.
    """
    if "state_dict" not in checkpoint:
        raise CheckpointError(f"{source}: not a Lightning checkpoint (no 'state_dict')")
    check_finite_tensors(checkpoint["state_dict"], source)
    return state_shapes(checkpoint["state_dict"])


def check_finite_tensors(
    tensors: Mapping[str, torch.Tensor] | Iterator[tuple[str, torch.Tensor]], source: str
) -> None:
    """Raise :class:`CheckpointError` naming the first floating tensor of ``tensors`` (a state dict, or
    ``(name, tensor)`` pairs) holding NaN or Inf (such a model only produces non-finite output, which no
    command writes)."""
    check_finite_weights(
        dict(tensors) if not isinstance(tensors, Mapping) else tensors, source, CheckpointError
    )


def check_finite_state(module: torch.nn.Module, source: str) -> None:
    """:func:`check_finite_tensors` on the parameters and buffers of ``module``."""
    check_finite_tensors(iter((*module.named_parameters(), *module.named_buffers())), source)


class CheckedCheckpointIO(TorchCheckpointIO):
    """The trainer's checkpoint reader and writer (Lightning's ``CheckpointIO`` plugin API).

    Reads go through :func:`load_checkpoint` (local file, ``weights_only``, structure and class paths).
    Writes go through a temporary file in the checkpoint's own folder, fsynced, then renamed over the
    target (:func:`~skeleton_mamba.io.atomic.atomic_open`): a full disk or an interruption leaves
    the previous checkpoint of that name intact and no partial file under the final name (Lightning's own
    writer stages the file in the system temporary folder and moves it, which is a copy across file
    systems).
    """

    def save_checkpoint(
        self, checkpoint: dict[str, Any], path: Any, storage_options: Any | None = None
    ) -> None:
        if storage_options is not None:
            raise TypeError(f"{type(self).__name__} writes local files: storage_options is not supported")
        with atomic_open(os.fspath(path), "wb") as handle:
            torch.save(store_paths_relative(checkpoint, path), handle)

    def load_checkpoint(
        self, path: Any, map_location: Callable | Any = None, weights_only: bool | None = None
    ) -> dict[str, Any]:
        if weights_only is False:
            raise CheckpointError(f"{path}: checkpoints are read with weights_only=True only")
        return load_checkpoint(os.fspath(path), map_location)


def use_checked_checkpoint_io(trainer: Any) -> None:
    """Make :class:`CheckedCheckpointIO` the checkpoint reader and writer of ``trainer`` (a Lightning
    ``Trainer``) unless a recipe configured a checkpoint plugin of its own."""
    if type(trainer.strategy.checkpoint_io) is TorchCheckpointIO:
        trainer.strategy.checkpoint_io = CheckedCheckpointIO()
