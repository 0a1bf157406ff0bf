"""The task-module base: the backbone (and other config dataclasses) as hyperparameters.

Task modules take a :class:`~skeleton_mamba.SkeletonMambaConfig` (``backbone``) and, where their network
has its own settings, a config dataclass (``EMMConfig``); checkpoints store them as plain dicts and lists
so that they load with ``weights_only=True`` (:mod:`skeleton_mamba.tasks.training.backbone_config`).
"""

from __future__ import annotations

import inspect

import lightning.pytorch as pl
from lightning.pytorch import LightningModule

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.training.backbone_config import backbone_config, plain_backbone_config

__all__ = ["BackboneModule", "attached_trainer"]


def attached_trainer(module: LightningModule) -> pl.Trainer | None:
    """The Trainer ``module`` runs in, or None outside one (built alone, or run by Fabric).

    LightningModule has no public "is attached" check: its ``trainer`` property raises a RuntimeError when
    no Trainer is attached, and under Fabric returns a stand-in that forwards to the Fabric object.
    """
    if module.fabric is not None:
        return None
    try:
        return module.trainer
    except RuntimeError:
        return None


class BackboneModule(LightningModule):
    """A LightningModule built on a SkeletonMamba backbone (recipes: ``backbones/skeleton_mamba.yaml``)."""

    def save_backbone_hyperparameters(
        self,
        backbone: SkeletonMambaConfig | dict | None,
        ignore: tuple[str, ...] = (),
        optional: bool = False,
    ) -> SkeletonMambaConfig | None:
        """Save the calling ``__init__``'s arguments but ``ignore``, with ``backbone`` as plain dicts.

        Returns the backbone's config (``None`` for ``backbone=None`` when ``optional``: the task's own
        encoder instead of a SkeletonMamba).
        """
        config = None if optional and backbone is None else backbone_config(backbone)
        self.save_hyperparameters(ignore=["backbone", *ignore], frame=inspect.currentframe().f_back)
        self.hparams["backbone"] = None if config is None else plain_backbone_config(config)
        return config
