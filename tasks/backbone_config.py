"""The backbone configuration as task modules receive and store it.

Recipes hand task modules a :class:`SkeletonMambaConfig` (LightningCLI parses the dataclass);
checkpoints store it as plain dicts and lists so that they load with ``weights_only=True``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from skeleton_mamba import MixerConfig, SkeletonMambaConfig

__all__ = ["backbone_config", "plain_backbone_config"]


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
