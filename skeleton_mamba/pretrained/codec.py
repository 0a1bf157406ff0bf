"""A pretrained folder's ``config.json``: its file names, format and JSON codec of ``__init__`` arguments.

``config.json`` holds the format name and version, the network's class and its ``__init__`` arguments.
Config dataclasses (:class:`~skeleton_mamba.SkeletonMambaConfig`, nested
:class:`~skeleton_mamba.MixerConfig`, a task's own) are stored as objects with a ``_type`` field naming the
class, tuples as lists, non-finite floats as the strings ``"inf"``, ``"-inf"``, ``"nan"`` (strict JSON).
:func:`decode_value` rebuilds every argument from the type annotations of the class's ``__init__`` and of the
dataclasses' fields, so the file names no code to import: ``_type`` is only compared with the annotated
class.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import os
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from skeleton_mamba.config import ConfigValueError
from skeleton_mamba.io.bounded_read import read_json
from skeleton_mamba.pretrained.checks import MAX_CONFIG_BYTES

__all__ = [
    "CARD_NAME",
    "CONFIG_NAME",
    "FOLDER_FILES",
    "FORMAT",
    "FORMAT_VERSION",
    "WEIGHTS_NAME",
    "PretrainedError",
    "class_name",
    "decode_value",
    "encode_value",
    "read_pretrained_config",
    "type_hints",
]

FORMAT = "skeleton-mamba-pretrained"
FORMAT_VERSION = 1
CONFIG_NAME = "config.json"
WEIGHTS_NAME = "model.safetensors"
CARD_NAME = "README.md"
FOLDER_FILES = (CONFIG_NAME, WEIGHTS_NAME, CARD_NAME)
"""The three files of a folder, the ones downloaded from and uploaded to the Hub."""
_NON_FINITE = {"inf": math.inf, "-inf": -math.inf, "nan": math.nan}


class PretrainedError(ValueError):
    """A folder or Hub id that is not a usable pretrained network (the message names the file and fault)."""


def class_name(cls: type) -> str:
    """The name a ``config.json`` stores for ``cls``: ``module.QualName``.

    Examples:
        >>> from skeleton_mamba import SkeletonMamba
        >>> class_name(SkeletonMamba)
        'skeleton_mamba.model.SkeletonMamba'
    """
    return f"{cls.__module__}.{cls.__qualname__}"


def type_hints(obj: Any) -> dict[str, Any]:
    """``obj``'s resolved annotations; empty when one does not resolve (values then pass as stored)."""
    try:
        return typing.get_type_hints(obj)
    except (NameError, TypeError):
        return {}


def encode_value(value: Any, where: str) -> Any:
    """``value`` as JSON data: dataclasses as ``{"_type": name, field: ...}``, tuples as lists, non-finite
    floats as strings. Raises :class:`PretrainedError` (naming ``where``) for anything else.

    Examples:
        >>> import math
        >>> from skeleton_mamba import SkeletonMambaConfig
        >>> encode_value({"window": (150, 75), "clip": math.inf}, "init")
        {'window': [150, 75], 'clip': 'inf'}
        >>> encode_value(SkeletonMambaConfig(dim=32, depth=1), "init.config")["_type"]
        'SkeletonMambaConfig'
    """
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


def decode_value(value: Any, hint: Any, where: str) -> Any:
    """Rebuild a value :func:`encode_value` wrote, guided by the annotation ``hint`` (``Any``: as stored).

    Raises:
        PretrainedError: ``value`` does not fit ``hint`` (naming ``where``).

    Examples:
        >>> decode_value([150, 75], tuple[int, int], "init.window")
        (150, 75)
        >>> decode_value("inf", float, "init.clip")
        inf
        >>> from skeleton_mamba import SkeletonMambaConfig
        >>> config = SkeletonMambaConfig(dim=32, depth=1)
        >>> decode_value(encode_value(config, "config"), SkeletonMambaConfig, "config") == config
        True
        >>> decode_value("8", int, "init.depth")
        Traceback (most recent call last):
        ...
        skeleton_mamba.pretrained.codec.PretrainedError: init.depth: expected int, got '8'
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
        hints = type_hints(hint)
        kwargs = {
            name: decode_value(item, hints.get(name, Any), f"{where}.{name}")
            for name, item in value.items()
            if name != "_type"
        }
        try:
            return hint(**kwargs)
        except ConfigValueError as err:  # a field out of its range, named by its place in the file
            raise PretrainedError(f"{where}.{err.field} = {err.value!r}: {err.rule}") from err
        except (TypeError, ValueError) as err:  # another check of the dataclass on its fields
            raise PretrainedError(f"{where}: {hint.__name__} refused its fields ({err})") from err
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
