"""Config dataclasses (the backbone's and the networks') as task modules receive and store them.

Recipes hand task modules a :class:`SkeletonMambaConfig` or a network's config (LightningCLI parses the
dataclass); checkpoints store them as plain dicts and lists so that they load with ``weights_only=True``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.errors import InputError

__all__ = ["backbone_config", "config_from", "derived_backbone", "plain_backbone_config"]

_DEFAULTS = {f.name: f.default for f in dataclasses.fields(SkeletonMambaConfig)}


def derived_backbone(config: SkeletonMambaConfig | None, owner: str, **derived) -> SkeletonMambaConfig:
    """``config`` (None: the defaults) with the fields that ``owner`` derives (from the data, its own settings
    or its representation) set to ``derived``.

    A backbone setting is given in one place: a field ``config`` sets to a value other than its default and
    other than the derived one would be overwritten, so it is refused instead (the same value, or the default,
    is accepted).

    Raises:
        InputError: one line naming each such field, both values and where the value comes from.
    """
    config = config or SkeletonMambaConfig()
    clashes = [
        f"backbone.{name} = {getattr(config, name)!r} but {owner} sets {value!r}"
        for name, value in derived.items()
        if getattr(config, name) not in (value, _DEFAULTS[name])
    ]
    if clashes:
        raise InputError(
            f"{'; '.join(clashes)}: a backbone setting is given in one place; remove it from the backbone "
            f"({owner} derives {', '.join(derived)})"
        )
    return dataclasses.replace(config, **derived)


def backbone_config(value: SkeletonMambaConfig | Mapping | None) -> SkeletonMambaConfig:
    """A :class:`SkeletonMambaConfig` from a config, a plain mapping (checkpoint hparams) or ``None``."""
    if value is None:
        return SkeletonMambaConfig()
    if isinstance(value, SkeletonMambaConfig):
        return value
    fields = dict(value)
    mixer = fields.get("mixer")
    if isinstance(mixer, Mapping):
        mixer = dict(mixer)
        for pair in ("A_init_range", "dt_limit"):
            if pair in mixer:
                mixer[pair] = tuple(mixer[pair])
        fields["mixer"] = MixerConfig(**mixer)
    return SkeletonMambaConfig(**fields)


def plain_backbone_config(config: SkeletonMambaConfig) -> dict:
    """The config as plain dicts and lists (checkpoints load with ``weights_only=True``)."""

    def plain(value):
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        if isinstance(value, list | tuple):
            return [plain(v) for v in value]
        return value

    return plain(dataclasses.asdict(config))


def config_from(cls: type, value: object | Mapping | None):
    """A ``cls`` config dataclass from a config, a plain mapping (checkpoint hparams) or ``None`` (defaults).

    Lists become tuples where the field's default is a tuple (checkpoints store tuples as lists).
    """
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    defaults = cls()
    fields = {
        name: tuple(v) if isinstance(v, list) and isinstance(getattr(defaults, name, None), tuple) else v
        for name, v in dict(value).items()
    }
    return cls(**fields)
