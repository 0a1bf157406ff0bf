"""``save_pretrained`` / ``from_pretrained`` / ``push_to_hub``: networks as Hugging Face Hub folders.

A folder (local, or a Hub repository) holds three files:

- ``config.json``: the format name and version, the network's class and its ``__init__`` arguments; config
  dataclasses (:class:`~skeleton_mamba.SkeletonMambaConfig`, nested :class:`~skeleton_mamba.MixerConfig`,
  a task's own) are stored as objects with a ``_type`` field naming the class, tuples as lists, non-finite
  floats as the strings ``"inf"``, ``"-inf"``, ``"nan"`` (strict JSON). Loading rebuilds every argument
  from the type annotations of the class's ``__init__`` and of the dataclasses' fields, so the file names
  no code to import: ``_type`` is only compared with the annotated class.
- ``model.safetensors``: the ``state_dict`` (parameters and persistent buffers, such as data statistics).
  It is read with ``safetensors``, which holds tensors and a JSON header only: nothing is unpickled.
- ``README.md``: a model card (Hub YAML front matter; task, skeleton, sizes, the training recipe and data
  and test metrics when given, citations).

The mixin records the arguments a network was built with (in ``__new__``, before ``__init__`` runs), so a
network only inherits from :class:`PretrainedMixin`. ``huggingface_hub`` and ``safetensors`` are imported
inside the methods that use them: the backbone itself needs torch and einops only.
"""

from __future__ import annotations

import copy
import dataclasses
import inspect
import json
import math
import os
import re
import tempfile
import types
import typing
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from skeleton_mamba.atomic import atomic_path
from skeleton_mamba.bounded_read import read_json
from skeleton_mamba.config import SkeletonMambaConfig
from skeleton_mamba.pretrained_checks import (
    MAX_CONFIG_BYTES,
    MAX_PARAMETERS,
    check_finite_weights,
    check_header_fits,
    check_sizes,
    meta_state,
    read_safetensors_header,
    total_values,
)

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

FORMAT = "skeleton-mamba-pretrained"
FORMAT_VERSION = 1
CONFIG_NAME = "config.json"
WEIGHTS_NAME = "model.safetensors"
CARD_NAME = "README.md"
_HUB_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*/[A-Za-z0-9][A-Za-z0-9_.-]*$")
_NON_FINITE = {"inf": math.inf, "-inf": -math.inf, "nan": math.nan}

# BibTeX of the papers a card cites, by the keys of the project's docs/references.md.
CITATIONS: dict[str, str] = {
    "EgoMusic": """@inproceedings{nguyen2025egomusic,
  title = {EgoMusic-driven Human Dance Motion Estimation with Skeleton Mamba},
  author = {Nguyen, Q. and Le, N. and Huang, B. and others},
  booktitle = {ICCV},
  year = {2025},
  eprint = {2508.10522},
  archivePrefix = {arXiv}
}""",
    "Mamba-2": """@inproceedings{dao2024transformers,
  title = {Transformers are {SSMs}: Generalized Models and Efficient Algorithms Through Structured State
           Space Duality},
  author = {Dao, Tri and Gu, Albert},
  booktitle = {ICML},
  year = {2024},
  eprint = {2405.21060},
  archivePrefix = {arXiv}
}""",
    "QEAN": """@article{zhou2024qean,
  title = {{QEAN}: Quaternion-Enhanced Attention Network for Visual Dance Generation},
  author = {Zhou, Z. and Huo, Y. and Huang, G. and others},
  journal = {arXiv preprint arXiv:2403.11626},
  year = {2024}
}""",
    "EDGE": """@inproceedings{tseng2023edge,
  title = {{EDGE}: Editable Dance Generation From Music},
  author = {Tseng, Jonathan and Castellon, Rodrigo and Liu, C. Karen},
  booktitle = {CVPR},
  year = {2023},
  eprint = {2211.10658},
  archivePrefix = {arXiv}
}""",
    "MDM": """@inproceedings{tevet2023mdm,
  title = {Human Motion Diffusion Model},
  author = {Tevet, G. and Raab, S. and Gordon, B. and others},
  booktitle = {ICLR},
  year = {2023},
  eprint = {2209.14916},
  archivePrefix = {arXiv}
}""",
    "PYSKL": """@inproceedings{duan2022pyskl,
  title = {{PYSKL}: Towards Good Practices for Skeleton Action Recognition},
  author = {Duan, Haodong and Wang, Jiaqi and Chen, Kai and Lin, Dahua},
  booktitle = {ACM Multimedia},
  year = {2022},
  eprint = {2205.09443},
  archivePrefix = {arXiv}
}""",
}


class PretrainedError(ValueError):
    """A folder or Hub id that is not a usable pretrained network (the message names the file and fault)."""


def class_name(cls: type) -> str:
    """The name a ``config.json`` stores for ``cls``: ``module.QualName``."""
    return f"{cls.__module__}.{cls.__qualname__}"


# ---------------------------------------------------------------------------------------------- values


def encode_value(value: Any, where: str) -> Any:
    """``value`` as JSON data: dataclasses as ``{"_type": name, field: ...}``, tuples as lists, non-finite
    floats as strings. Raises :class:`PretrainedError` (naming ``where``) for anything else."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {
            f.name: encode_value(getattr(value, f.name), f"{where}.{f.name}")
            for f in dataclasses.fields(value)
        }
        return {"_type": type(value).__name__, **fields}
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    if isinstance(value, float):
        return (
            value
            if math.isfinite(value)
            else ("nan" if math.isnan(value) else ("inf" if value > 0 else "-inf"))
        )
    if isinstance(value, (list, tuple)):
        return [encode_value(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, Mapping) and all(isinstance(k, str) for k in value):
        return {k: encode_value(v, f"{where}.{k}") for k, v in value.items()}
    raise PretrainedError(f"{where}: a {type(value).__name__} cannot be stored in {CONFIG_NAME}")


def _hints(obj: Any) -> dict[str, Any]:
    try:
        return typing.get_type_hints(obj)
    except (NameError, TypeError):  # an annotation that does not resolve: values pass through as stored
        return {}


def decode_value(value: Any, hint: Any, where: str) -> Any:
    """Rebuild a value :func:`encode_value` wrote, guided by the annotation ``hint`` (``Any``: as stored).

    Raises:
        PretrainedError: ``value`` does not fit ``hint`` (naming ``where``).
    """
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        options = typing.get_args(hint)
        if value is None and type(None) in options:
            return None
        errors = []
        for option in (o for o in options if o is not type(None)):
            try:
                return decode_value(value, option, where)
            except PretrainedError as err:
                errors.append(str(err))
        raise PretrainedError(errors[0] if errors else f"{where}: {value!r} does not fit {hint}")
    if inspect.isclass(hint) and dataclasses.is_dataclass(hint):
        if not isinstance(value, dict):
            raise PretrainedError(f"{where}: expected a {hint.__name__} object, got {value!r}")
        stored = value.get("_type", hint.__name__)
        if stored != hint.__name__:
            raise PretrainedError(f"{where}: stores a {stored!r}, the class expects a {hint.__name__}")
        fields = {f.name: f for f in dataclasses.fields(hint)}
        unknown = sorted(set(value) - set(fields) - {"_type"})
        if unknown:
            raise PretrainedError(f"{where}: {hint.__name__} has no field {unknown[0]!r}")
        hints = _hints(hint)
        kwargs = {
            name: decode_value(item, hints.get(name, Any), f"{where}.{name}")
            for name, item in value.items()
            if name != "_type"
        }
        return hint(**kwargs)
    if origin in (list, tuple):
        if not isinstance(value, list):
            raise PretrainedError(f"{where}: expected a list, got {value!r}")
        args = typing.get_args(hint)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                raise PretrainedError(f"{where}: expected {len(args)} values, got {len(value)}")
            return tuple(decode_value(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
        item = args[0] if args else Any
        items = [decode_value(v, item, f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if hint is float:
        if isinstance(value, str) and value in _NON_FINITE:
            return _NON_FINITE[value]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise PretrainedError(f"{where}: expected a number, got {value!r}")
    if hint in (int, str, bool):
        if type(value) is not hint:
            raise PretrainedError(f"{where}: expected {hint.__name__}, got {value!r}")
        return value
    return value  # dict, Any, an unresolved annotation: JSON data as stored


# ---------------------------------------------------------------------------------------------- folders


def resolve_pretrained(
    source: str | os.PathLike[str],
    *,
    revision: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    local_files_only: bool = False,
    token: str | bool | None = None,
) -> Path:
    """The local folder of ``source``: a folder as given, or a Hub id (``org/name``) through the Hugging Face
    cache (downloaded once; ``HF_HUB_OFFLINE=1`` or ``local_files_only`` reads the cache only).

    Raises:
        PretrainedError: neither a folder nor a Hub id, or the Hub id cannot be resolved.
    """
    text = os.fspath(source)
    path = Path(text).expanduser()
    if path.is_dir():
        return path
    if path.exists():
        raise PretrainedError(
            f"{text}: is a file; a from_pretrained folder ({CONFIG_NAME} + {WEIGHTS_NAME}) "
            "or a Hub id is expected"
        )
    if not _HUB_ID.match(text) or text.startswith((".", "~")):
        raise PretrainedError(f"{text}: no such folder, and not a Hub id (org/name)")
    from huggingface_hub import snapshot_download  # lazy: optional dependency (Hub folders only)
    from huggingface_hub.utils import (  # lazy: optional dependency
        HfHubHTTPError,
        HFValidationError,
        LocalEntryNotFoundError,
    )

    try:
        folder = snapshot_download(
            text,
            revision=revision,
            cache_dir=cache_dir,
            local_files_only=local_files_only,
            token=token,
            allow_patterns=[CONFIG_NAME, WEIGHTS_NAME, CARD_NAME],
            library_name="skeleton-mamba",
        )
    except (LocalEntryNotFoundError, HFValidationError, HfHubHTTPError, OSError) as err:
        first = str(err).strip().splitlines()
        raise PretrainedError(
            f"{text}: no such folder, and the Hub id does not resolve ({type(err).__name__}: "
            f"{first[0] if first else ''})"
        ) from err
    return Path(folder)


def read_pretrained_config(folder: str | os.PathLike[str]) -> dict:
    """``folder``'s ``config.json``, checked for the format name and version.

    Raises:
        PretrainedError: missing, not JSON, another format or a newer version.
    """
    path = Path(folder) / CONFIG_NAME
    try:
        config = read_json(path, max_bytes=MAX_CONFIG_BYTES, what=CONFIG_NAME, error=PretrainedError)
    except FileNotFoundError:
        raise PretrainedError(f"{path}: missing (not a from_pretrained folder)") from None
    if not isinstance(config, dict) or config.get("format") != FORMAT:
        raise PretrainedError(
            f"{path}: not a {FORMAT} config (its 'format' is "
            f"{config.get('format') if isinstance(config, dict) else None!r})"
        )
    version = config.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise PretrainedError(
            f"{path}: format_version {version!r}, this version reads {FORMAT_VERSION} and older"
        )
    if not isinstance(config.get("class"), str) or not isinstance(config.get("init", {}), dict):
        raise PretrainedError(f"{path}: needs a 'class' name and an 'init' object")
    return config


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file beside it (:mod:`skeleton_mamba.atomic`)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def push_folder_to_hub(
    folder: str | os.PathLike[str],
    repo_id: str,
    *,
    private: bool | None = None,
    token: str | None = None,
    revision: str | None = None,
    commit_message: str = "Upload Skeleton Mamba network",
) -> Any:
    """Create the Hub model repository ``repo_id`` (when missing) and upload ``folder``'s three files."""
    read_pretrained_config(folder)
    from huggingface_hub import HfApi  # lazy: optional dependency (Hub uploads only)

    api = HfApi(token=token)
    api.create_repo(repo_id, private=private, exist_ok=True, repo_type="model")
    return api.upload_folder(
        repo_id=repo_id,
        folder_path=os.fspath(folder),
        revision=revision,
        commit_message=commit_message,
        allow_patterns=[CONFIG_NAME, WEIGHTS_NAME, CARD_NAME],
        repo_type="model",
    )


# ---------------------------------------------------------------------------------------------- card


def _backbone_config(model: torch.nn.Module) -> SkeletonMambaConfig | None:
    for module in model.modules():
        config = getattr(module, "config", None)
        if isinstance(config, SkeletonMambaConfig):
            return config
    return None


def _table(rows: Mapping[str, Any]) -> list[str]:
    return ["| | |", "| --- | --- |", *(f"| {k} | {v} |" for k, v in rows.items())]


def model_card(model: torch.nn.Module, info: Mapping[str, Any] | None = None) -> str:
    """The README.md of a folder: Hub front matter, task, skeleton and sizes, recipe, data, metrics, citation.

    ``info`` (all optional): ``task``, ``recipe``, ``module`` (class path), ``hparams`` (the module's),
    ``data`` (class path), ``data_hparams``, ``metrics`` ({name: value} of a test run), ``trained``
    ({"epoch": .., "global_step": ..}).
    """
    info = dict(info or {})
    cls = type(model)
    keys = list(dict.fromkeys([*info.get("citations", ()), *getattr(cls, "pretrained_citations", ())]))
    backbone = _backbone_config(model)
    params = sum(p.numel() for p in model.parameters())
    task = info.get("task") or getattr(cls, "pretrained_task", "")
    tags = ["skeleton-mamba", "mamba2", "human-motion", "pytorch"]
    lines = ["---", "library_name: skeleton-mamba", "license: apache-2.0", "tags:", *(f"- {t}" for t in tags)]
    lines += ["---", "", f"# {cls.__name__}", ""]
    if task:
        lines += [f"{task}", ""]
    sizes: dict[str, Any] = {"class": f"`{class_name(cls)}`", "parameters": f"{params:,}"}
    if backbone is not None:
        mixer = backbone.mixer
        sizes.update(
            skeleton=f"`{backbone.skeleton}`",
            **{"width D": backbone.dim, "blocks N": backbone.depth, "MLP width": backbone.mlp_dim},
            **{"temporal scan": "causal (streams frame by frame)" if backbone.causal else "bidirectional"},
            **{
                "cross-attention context": backbone.context_dim
                if backbone.context_dim is not None
                else "none"
            },
        )
        if mixer is not None:
            sizes.update({"SSD state N / head width": f"{mixer.d_state} / {mixer.headdim}"})
    lines += ["## Network", "", *_table(sizes), ""]
    if info.get("recipe") or info.get("module") or info.get("hparams"):
        lines += ["## Training", ""]
        if info.get("recipe"):
            lines += [f"Recipe: `{info['recipe']}`.", ""]
        if info.get("module"):
            lines += [f"Lightning module: `{info['module']}`.", ""]
        if info.get("trained"):
            lines += [", ".join(f"{k} {v}" for k, v in info["trained"].items()) + ".", ""]
        if info.get("hparams"):
            lines += [
                "Hyper-parameters:",
                "",
                "```json",
                json.dumps(encode_value(info["hparams"], "hparams"), indent=2),
                "```",
                "",
            ]
    if info.get("data") or info.get("data_hparams"):
        lines += ["## Data", ""]
        if info.get("data"):
            lines += [f"Data module: `{info['data']}`.", ""]
        if info.get("data_hparams"):
            lines += [
                "```json",
                json.dumps(encode_value(info["data_hparams"], "data_hparams"), indent=2),
                "```",
                "",
            ]
    lines += ["## Metrics", ""]
    metrics = info.get("metrics")
    if metrics:
        lines += ["| metric | value |", "| --- | --- |", *(f"| {k} | {v} |" for k, v in metrics.items()), ""]
    else:
        lines += ["No test was run for this folder.", ""]
    lines += [
        "## Use",
        "",
        "```python",
        f"from {cls.__module__} import {cls.__name__}",
        "",
        f'model = {cls.__name__}.from_pretrained("path/or/org-name")  # safetensors only, eval mode',
        "```",
        "",
    ]
    if keys:
        cited = ", ".join(f"[{k}]" for k in keys)
        lines += [
            "## Citation",
            "",
            f"Papers, by the keys of the project's `docs/references.md`: {cited}.",
            "",
        ]
        lines += ["```bibtex", *(CITATIONS[k] for k in keys if k in CITATIONS), "```", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- mixin


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
        from safetensors.torch import save  # lazy: optional dependency (pretrained folders only)

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
        ``cls`` and every size within :data:`~skeleton_mamba.size_bounds.SIZE_BOUNDS`. Nothing is built.

        Raises:
            PretrainedError: naming ``source`` and the argument at fault.
        """
        stored = config.get("class")
        if stored != class_name(cls):
            raise PretrainedError(f"{source}: holds a {stored!r}, not a {class_name(cls)}")
        hints = _hints(cls.__init__)
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
        ``__init__`` arguments. The order of :mod:`skeleton_mamba.pretrained_checks`: sizes, the network
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
        from safetensors import SafetensorError  # lazy: optional dependency (pretrained folders only)
        from safetensors.torch import load_file  # lazy: optional dependency (pretrained folders only)

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
        anything is allocated (:mod:`skeleton_mamba.pretrained_checks`).

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
