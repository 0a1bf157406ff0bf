"""The task-module base: the backbone (and other config dataclasses) as hyperparameters.

Task modules take a :class:`~skeleton_mamba.SkeletonMambaConfig` (``backbone``) and, where their network
has its own settings, a config dataclass (``EMMConfig``); checkpoints store them as plain dicts and lists
so that they load with ``weights_only=True`` (:mod:`skeleton_mamba.tasks.training.backbone_config`).

What follows from the data reaches a task module in two ways only, both from the data module's
:class:`~skeleton_mamba.tasks.training.base_data.DataContract`: its sizes and rates as ``__init__`` arguments
(LightningCLI links them), and the contract itself through :meth:`BackboneModule.setup`, which keeps it as
:attr:`BackboneModule.contract` (what the test loops read, e.g. ``music_cache_dir``) and hands its training
statistics to the module's :meth:`~BackboneModule.set_data_statistics` once, at ``fit`` (a resumed run then
restores the checkpoint's copy over them). A module never reads its data module's hyper-parameters.
"""

from __future__ import annotations

import inspect
from typing import Any

import lightning.pytorch as pl
from lightning.pytorch import LightningModule

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.training.backbone_config import backbone_config, plain_backbone_config
from skeleton_mamba.tasks.training.base_data import DataContract, data_contract

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
    """A LightningModule built on a SkeletonMamba backbone (recipes: ``backbones/skeleton_mamba.yaml``).

    Attributes:
        contract: the data module's :class:`DataContract` as :meth:`setup` received it (None before ``setup``,
            outside a Trainer or without a data module; its ``statistics`` are filled at ``fit`` only).
    """

    contract: DataContract | None = None

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

    def data_contract(self, include_statistics: bool = True) -> DataContract | None:
        """The :class:`DataContract` of the Trainer's data module (None outside a Trainer or without one)."""
        datamodule = getattr(attached_trainer(self), "datamodule", None)
        return None if datamodule is None else data_contract(datamodule, include_statistics)

    def setup(self, stage: str) -> None:
        """The data module's contract to :attr:`contract`; at fit its training statistics to
        :meth:`set_data_statistics` (when it has any)."""
        self.contract = self.data_contract(include_statistics=stage == "fit")
        if self.contract is not None and self.contract.statistics is not None:
            self.set_data_statistics(self.contract.statistics)

    def set_data_statistics(self, statistics: Any) -> None:
        """Take the training split's statistics (:attr:`DataContract.statistics`: the task's own dataclass of
        named tensors); a task with data-dependent normalisation overrides this."""
