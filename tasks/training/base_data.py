"""The data-module base of the tasks: datasets by split and the four dataloaders from one factory.

A task's data module fills ``self.datasets`` (split name -> dataset) in ``setup`` and sets
``batch_size`` and ``num_workers``; :meth:`SplitDataModule._dataloader_factory` makes every loader
(shuffled for ``train`` only), ``predict`` reads the test split, and :meth:`loader_options` adds what a
task's loaders need beyond that (a ``collate_fn``, ``drop_last``, pinned memory).
"""

from __future__ import annotations

from typing import Any

from lightning.pytorch import LightningDataModule
from torch.utils.data import DataLoader, Dataset

__all__ = ["SplitDataModule"]


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

    def loader_options(self, split: str) -> dict[str, Any]:
        """DataLoader arguments of ``split`` beyond dataset, batch size, shuffling and workers."""
        return {}

    def _dataloader_factory(self, split: str) -> DataLoader:
        return DataLoader(
            self.datasets[split],
            batch_size=self.batch_size,
            shuffle=split == "train",
            num_workers=self.num_workers,
            **self.loader_options(split),
        )

    def train_dataloader(self) -> DataLoader:
        return self._dataloader_factory("train")

    def val_dataloader(self) -> DataLoader:
        return self._dataloader_factory("val")

    def test_dataloader(self) -> DataLoader:
        return self._dataloader_factory("test")

    def predict_dataloader(self) -> DataLoader:
        return self._dataloader_factory("test")
