"""The data-module base of the tasks: datasets by split and the four dataloaders from one factory.

A task's data module fills ``self.datasets`` (split name -> dataset) in ``setup`` and sets
``batch_size`` and ``num_workers``; :meth:`SplitDataModule._dataloader_factory` makes every loader
(shuffled for ``train`` only), ``predict`` reads the test split, and :meth:`loader_options` adds what a
task's loaders need beyond that (a ``collate_fn``, ``drop_last``, pinned memory).

What follows from the data is handed to the model in one typed place, :class:`DataContract`: the sizes and
rates fixed when the data module is built (``music_dim``, ``fps``, ``skeleton``, ...; LightningCLI links each
to the model's argument of that name,
:func:`~skeleton_mamba.tasks.training.lightning_cli.data_to_model_links`)
and the per-channel statistics of the training split (:meth:`SplitDataModule.training_statistics`, set once
the split is read). :meth:`~skeleton_mamba.tasks.training.base_module.BackboneModule.setup` hands the contract
to the model at every stage (``module.contract``: e.g. the music cache of the test loop's beats) and its
statistics at ``fit``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import torch
from lightning.pytorch import LightningDataModule
from torch.utils.data import DataLoader, Dataset

__all__ = ["DataContract", "SplitDataModule", "data_contract"]


@dataclasses.dataclass(frozen=True)
class DataContract:
    """What a data module's samples fix for the model (None: the data does not fix it).

    Attributes:
        music_dim: music features per frame (the ``music`` tensors' last size).
        fps: motion and music frame rate.
        skeleton: skeleton layout name (:mod:`skeleton_mamba.skeletons`).
        num_classes: action classes. in_channels: channels per joint.
        image_size: side of the egocentric frames (pixels).
        seed_frames, music_frames, predict_frames, generate_frames: window lengths (frames).
        music_cache_dir: where the data module caches music features (None: the toolkit's default); the test
            loops compute their protocol's music beats through the same cache.
        statistics: per-channel statistics of the training split, by name (empty before ``setup("fit")``;
            the names are the task's: ``motion`` / ``music`` training frames, ``feature_mean`` ...).
    """

    music_dim: int | None = None
    fps: float | None = None
    skeleton: str | None = None
    num_classes: int | None = None
    in_channels: int | None = None
    image_size: int | None = None
    seed_frames: int | None = None
    music_frames: int | None = None
    predict_frames: int | None = None
    generate_frames: int | None = None
    music_cache_dir: str | None = None
    statistics: Mapping[str, torch.Tensor] = dataclasses.field(default_factory=dict)


_CONTRACT_SIZES = tuple(f.name for f in dataclasses.fields(DataContract) if f.name != "statistics")


def data_contract(datamodule: LightningDataModule, include_statistics: bool = True) -> DataContract:
    """The :class:`DataContract` of any data module: its attributes of the contract's names, and (with
    ``include_statistics``) its ``training_statistics()`` where it has them (a data module not built on
    :class:`SplitDataModule`)."""
    statistics = getattr(datamodule, "training_statistics", None) if include_statistics else None
    return DataContract(
        **{name: getattr(datamodule, name, None) for name in _CONTRACT_SIZES},
        statistics=dict(statistics()) if callable(statistics) else {},
    )


class SplitDataModule(LightningDataModule):
    """A LightningDataModule whose loaders read ``self.datasets[split]``.

    Attributes:
        datasets: split name (``train``, ``val``, ``test``) -> dataset, filled by ``setup``.
        batch_size: per-device batch size (linked to the model where it has the argument).
        num_workers: DataLoader worker processes.
    """

    def __init__(self, batch_size: int, num_workers: int) -> None:
        super().__init__()
        self.batch_size = batch_size
        self.num_workers = num_workers
        self.datasets: dict[str, Dataset] = {}

    @property
    def contract(self) -> DataContract:
        """What the data fixes for the model (:class:`DataContract`)."""
        return data_contract(self)

    def training_statistics(self) -> dict[str, torch.Tensor]:
        """Per-channel statistics of the training split, by name (a task's data module says which);
        empty before the split is set up."""
        return {}

    def loader_options(self, split: str) -> dict[str, Any]:
        """DataLoader arguments of ``split`` beyond dataset, shuffling and workers, or replacing them (a
        ``batch_size`` of its own)."""
        return {}

    def _dataloader_factory(self, split: str) -> DataLoader:
        options = dict(batch_size=self.batch_size, shuffle=split == "train", num_workers=self.num_workers)
        return DataLoader(self.datasets[split], **{**options, **self.loader_options(split)})

    def train_dataloader(self) -> DataLoader:
        return self._dataloader_factory("train")

    def val_dataloader(self) -> DataLoader:
        return self._dataloader_factory("val")

    def test_dataloader(self) -> DataLoader:
        return self._dataloader_factory("test")

    def predict_dataloader(self) -> DataLoader:
        return self._dataloader_factory("test")
