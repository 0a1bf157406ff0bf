"""Config dataclasses (the backbone's and the networks') as task modules receive and store them.

Recipes hand task modules a :class:`SkeletonMambaConfig` or a network's config (LightningCLI parses the
dataclass); checkpoints store them as plain dicts and lists so that they load with ``weights_only=True``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from skeleton_mamba import MixerConfig, SkeletonMambaConfig

__all__ = ["backbone_config", "config_from", "plain_backbone_config"]


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
