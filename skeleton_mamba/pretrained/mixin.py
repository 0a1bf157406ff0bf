"""``save_pretrained`` / ``from_pretrained`` / ``push_to_hub``: networks as Hugging Face Hub folders.

A folder (local, or a Hub repository) holds three files:

- ``config.json``: the format name and version, the network's class and its ``__init__`` arguments, as
  :mod:`skeleton_mamba.pretrained.codec` encodes them (strict JSON; nothing in it names code to import).
- ``model.safetensors``: the ``state_dict`` (parameters and persistent buffers, such as data statistics).
  It is read with ``safetensors``, which holds tensors and a JSON header only: nothing is unpickled.
- ``README.md``: a model card (:mod:`skeleton_mamba.pretrained.card`).

This module holds :class:`PretrainedMixin`, which writes and reads the three files; the Hub client (a Hub id
to a local folder, uploads) is :mod:`skeleton_mamba.pretrained.hub`, and the checks made before anything is
allocated are :mod:`skeleton_mamba.pretrained.checks`. The mixin records the arguments a network was built
with (in ``__new__``, before ``__init__`` runs), so a network only inherits from :class:`PretrainedMixin`.
The public names of the codec, card and Hub modules are importable from here too.
"""

from __future__ import annotations

import copy
import inspect
import json
import os
import tempfile
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save

from skeleton_mamba.io.atomic import atomic_path
from skeleton_mamba.pretrained.card import CITATIONS, model_card
from skeleton_mamba.pretrained.checks import (
    MAX_PARAMETERS,
    check_finite_weights,
    check_header_fits,
    check_sizes,
    meta_state,
    read_safetensors_header,
    total_values,
)
from skeleton_mamba.pretrained.codec import (
    CARD_NAME,
    CONFIG_NAME,
    FORMAT,
    FORMAT_VERSION,
    WEIGHTS_NAME,
    PretrainedError,
    class_name,
    decode_value,
    encode_value,
    read_pretrained_config,
    type_hints,
)
from skeleton_mamba.pretrained.hub import push_folder_to_hub, resolve_pretrained

__all__ = [
    "CARD_NAME",
    "CITATIONS",
    "CONFIG_NAME",
    "FORMAT",
    "FORMAT_VERSION",
    "WEIGHTS_NAME",
    "PretrainedError",
    "PretrainedMixin",
    "class_name",
    "decode_value",
    "encode_value",
    "push_folder_to_hub",
    "read_pretrained_config",
    "resolve_pretrained",
]


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file beside it (:mod:`skeleton_mamba.io.atomic`)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


class PretrainedMixin:
    """``save_pretrained`` / ``from_pretrained`` / ``push_to_hub`` for an ``nn.Module`` (listed first in the
    bases: ``class Net(PretrainedMixin, nn.Module)``).

    Class attributes a network may set: ``pretrained_task`` (one line for the card),
    ``pretrained_citations`` (keys of :data:`CITATIONS`), ``pretrained_ignored_warnings`` (warning classes
    its ``__init__`` emits that loaded weights make moot, e.g. random initialisation).
    """

    pretrained_task: str = ""
    pretrained_citations: tuple[str, ...] = ()
    pretrained_ignored_warnings: tuple[type[Warning], ...] = ()

    def __new__(cls, *args: Any, **kwargs: Any):
        instance = super().__new__(cls)
        try:
            bound = inspect.signature(cls.__init__).bind(None, *args, **kwargs)
        except TypeError:  # copy / deepcopy build with no arguments, then restore __dict__
            return instance
        bound.apply_defaults()
        init: dict[str, Any] = {}
        parameters = inspect.signature(cls.__init__).parameters
        for name, value in list(bound.arguments.items())[1:]:
            kind = parameters[name].kind
            if kind is inspect.Parameter.VAR_KEYWORD:
                init.update(value)
            elif kind is not inspect.Parameter.VAR_POSITIONAL:
                init[name] = value
        object.__setattr__(instance, "_pretrained_init", copy.deepcopy(init))
        return instance

    def pretrained_init_args(self) -> dict[str, Any]:
        """The ``__init__`` arguments that rebuild this network (as it was built; a network may override)."""
        init = getattr(self, "_pretrained_init", None)
        if init is None:
            raise PretrainedError(f"{type(self).__name__}: its __init__ arguments were not recorded")
        return dict(init)

    def pretrained_config(self) -> dict[str, Any]:
        """The content of ``config.json``."""
        cls = type(self)
        init = {
            name: encode_value(value, f"{cls.__name__}.{name}")
            for name, value in self.pretrained_init_args().items()
        }
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "class": class_name(cls), "init": init}

    def save_pretrained(
        self,
        save_directory: str | os.PathLike[str],
        card_info: Mapping[str, Any] | None = None,
        extra_config: Mapping[str, Any] | None = None,
    ) -> Path:
        """Write ``config.json``, ``model.safetensors`` and ``README.md`` into ``save_directory`` (created).

        ``card_info``: what the model card says beyond the network (:func:`model_card`); ``extra_config``:
        more JSON entries of ``config.json`` (an exported folder's Lightning module). Each file is written
        to a temporary file beside it and renamed, ``config.json`` last.
        """
        folder = Path(save_directory)
        folder.mkdir(parents=True, exist_ok=True)
        config = self.pretrained_config()
        config.update({k: v for k, v in (extra_config or {}).items() if k not in config})
        state = self.state_dict()  # type: ignore[attr-defined]
        seen: set[tuple[int, int]] = set()
        tensors = {}
        for name, tensor in state.items():
            tensor = tensor.detach().cpu().contiguous()
            key = (tensor.untyped_storage().data_ptr(), tensor.storage_offset())
            tensors[name] = tensor.clone() if key in seen else tensor  # safetensors refuses shared memory
            seen.add(key)
        _write_atomic(
            folder / WEIGHTS_NAME, save(tensors, metadata={"format": "pt", "class": config["class"]})
        )
        _write_atomic(folder / CARD_NAME, model_card(self, card_info).encode("utf-8"))  # type: ignore[arg-type]
        _write_atomic(
            folder / CONFIG_NAME, (json.dumps(config, indent=2, allow_nan=False) + "\n").encode("utf-8")
        )
        return folder

    @classmethod
    def from_config(cls, config: Mapping[str, Any], source: str = CONFIG_NAME):
        """A freshly initialised network from a ``config.json`` dict (its class must be ``cls``).

        Raises:
            PretrainedError: another class, a size beyond its bound, or arguments that do not fit
                ``cls.__init__``.
        """
        return cls._build(cls.pretrained_kwargs(config, source), source)

    @classmethod
    def pretrained_kwargs(cls, config: Mapping[str, Any], source: str = CONFIG_NAME) -> dict[str, Any]:
        """The ``__init__`` arguments a ``config.json`` dict stores, decoded and checked: its class must be
        ``cls`` and every size within :data:`~skeleton_mamba.pretrained.size_bounds.SIZE_BOUNDS`. Nothing is
        built.

        Raises:
            PretrainedError: naming ``source`` and the argument at fault.
        """
        stored = config.get("class")
        if stored != class_name(cls):
            raise PretrainedError(f"{source}: holds a {stored!r}, not a {class_name(cls)}")
        hints = type_hints(cls.__init__)
        parameters = inspect.signature(cls.__init__).parameters
        takes_kwargs = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values())
        kwargs = {}
        for name, value in dict(config.get("init", {})).items():
            if name not in parameters and not takes_kwargs:
                raise PretrainedError(f"{source}: {cls.__name__} takes no argument {name!r}")
            kwargs[name] = decode_value(value, hints.get(name, Any), f"{source}: {cls.__name__}.{name}")
        check_sizes(kwargs, f"{source}: {cls.__name__}", PretrainedError)
        return kwargs

    @classmethod
    def _build(cls, kwargs: Mapping[str, Any], source: str, meta: bool = False):
        """``cls(**kwargs)`` (on the ``meta`` device: sizes only), its refusal naming ``source``."""
        with warnings.catch_warnings():
            for category in cls.pretrained_ignored_warnings:
                warnings.simplefilter("ignore", category)
            try:
                return meta_state(cls, kwargs) if meta else cls(**kwargs)
            except (TypeError, ValueError, KeyError, RuntimeError) as err:
                first = str(err).strip().splitlines()
                raise PretrainedError(
                    f"{source}: {cls.__name__}(...) refused its arguments ({first[0] if first else err!r})"
                ) from err

    @classmethod
    def check_pretrained_folder(cls, folder: str | os.PathLike[str], config: Mapping[str, Any]) -> dict:
        """Check ``folder`` (its ``config.json`` dict ``config``) before anything is allocated; returns the
        ``__init__`` arguments. The order of :mod:`skeleton_mamba.pretrained.checks`: sizes, the network
        built on ``meta`` and its value count, the safetensors header against it.

        Raises:
            PretrainedError: naming the file and what is wrong.
        """
        folder = Path(folder)
        source = str(folder / CONFIG_NAME)
        kwargs = cls.pretrained_kwargs(config, source)
        expected = cls._build(kwargs, source, meta=True)
        values = total_values(expected)
        if values > MAX_PARAMETERS:
            raise PretrainedError(
                f"{source}: {cls.__name__} of {values:,} values, more than a network's {MAX_PARAMETERS:,}"
            )
        weights = folder / WEIGHTS_NAME
        try:
            header = read_safetensors_header(weights, PretrainedError)
        except FileNotFoundError:
            raise PretrainedError(f"{weights}: missing (not a from_pretrained folder)") from None
        check_header_fits(header, expected, str(weights), cls.__name__, PretrainedError)
        return kwargs

    def load_pretrained_weights(
        self, path: str | os.PathLike[str], device: str | torch.device = "cpu"
    ) -> None:
        """Load ``model.safetensors`` into this network: its header is checked against the network (names,
        shapes, types) before any tensor is read, the tensors finite before any is copied.

        Raises:
            PretrainedError: an unreadable file, a missing or unexpected tensor, a shape or type that
                differs, a NaN or Inf.
        """
        name = type(self).__name__
        try:
            header = read_safetensors_header(path, PretrainedError)
        except FileNotFoundError:
            raise PretrainedError(f"{path}: missing (not a from_pretrained folder)") from None
        check_header_fits(header, self.state_dict(), str(path), name, PretrainedError)  # type: ignore[attr-defined]
        try:
            tensors = load_file(os.fspath(path), device=str(device))
        except (SafetensorError, OSError) as err:
            raise PretrainedError(f"{path}: not a safetensors file ({err})") from None
        check_finite_weights(tensors, str(path), PretrainedError)
        self.load_state_dict(tensors, strict=True)  # type: ignore[attr-defined]

    @classmethod
    def from_folder(cls, folder: str | os.PathLike[str], device: str | torch.device = "cpu"):
        """The network saved in the local ``folder``, checked (:meth:`check_pretrained_folder`) before it is
        built, in eval mode."""
        folder = Path(folder)
        config = read_pretrained_config(folder)
        kwargs = cls.check_pretrained_folder(folder, config)
        model = cls._build(kwargs, str(folder / CONFIG_NAME))
        model.load_pretrained_weights(folder / WEIGHTS_NAME, device)
        return model.to(device).eval()

    @classmethod
    def from_pretrained(
        cls,
        source: str | os.PathLike[str],
        *,
        revision: str | None = None,
        cache_dir: str | os.PathLike[str] | None = None,
        local_files_only: bool = False,
        token: str | bool | None = None,
        device: str | torch.device = "cpu",
    ):
        """The network saved in ``source`` (a folder or a Hub id ``org/name``), in eval mode; checked before
        anything is allocated (:mod:`skeleton_mamba.pretrained.checks`).

        Raises:
            PretrainedError: not such a folder, another class, a size beyond its bound, config or weights
                that do not fit, non-finite weights.
        """
        folder = resolve_pretrained(
            source, revision=revision, cache_dir=cache_dir, local_files_only=local_files_only, token=token
        )
        return cls.from_folder(folder, device)

    def push_to_hub(
        self,
        repo_id: str,
        *,
        card_info: Mapping[str, Any] | None = None,
        private: bool | None = None,
        token: str | None = None,
        revision: str | None = None,
        commit_message: str = "Upload Skeleton Mamba network",
    ) -> Any:
        """:meth:`save_pretrained` into a temporary folder, then upload it to the Hub model ``repo_id``."""
        with tempfile.TemporaryDirectory() as tmp:
            self.save_pretrained(tmp, card_info)
            return push_folder_to_hub(
                tmp, repo_id, private=private, token=token, revision=revision, commit_message=commit_message
            )
