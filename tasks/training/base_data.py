"""The data-module base of the tasks: datasets by split and the four dataloaders from one factory.

A task's data module fills ``self.datasets`` (split name -> dataset) in ``setup`` and sets
``batch_size`` and ``num_workers``; :meth:`SplitDataModule._dataloader_factory` makes every loader
(shuffled for ``train`` only), ``predict`` reads the test split, and :meth:`loader_options` adds what a
task's loaders need beyond that (a ``collate_fn``, ``drop_last``, pinned memory).

What follows from the data is handed to the model in one typed place, the data module's contract: a frozen
dataclass deriving from :class:`DataContract` (declared in the task's ``data.py``, named by the data module's
``contract_class``) that its ``contract`` property returns. Each field not marked :func:`unlinked` is a size
or rate fixed when the data module is built (``num_classes``, ``music_dim``, ...), and LightningCLI links it
to the model's constructor argument of the same name, or to the field of that name of one of the model's
config dataclasses (``network.seed_frames``;
:func:`~skeleton_mamba.tasks.training.contract_links.contract_links`, derived from the two classes, never
listed); a field the model takes nowhere fails at start in one line. The unlinked fields are what the module
reads at run time (``music_cache_dir``) and ``statistics``, the training split's per-channel statistics as a
task's own dataclass of named tensors (None before the split is read).
:meth:`~skeleton_mamba.tasks.training.base_module.BackboneModule.setup` hands the contract to the model at
every stage (``module.contract``) and its statistics at ``fit``."""

from __future__ import annotations

import dataclasses
from typing import Any

from lightning.pytorch import LightningDataModule
from torch.utils.data import DataLoader, Dataset

from skeleton_mamba.errors import InputError

__all__ = [
    "LINKED",
    "LINK_PREFIX",
    "ContractDataModule",
    "DataContract",
    "SplitDataModule",
    "data_contract",
    "linked_fields",
    "unlinked",
]


LINKED = "skeleton_mamba.linked"
"""The metadata key of a contract field: False for the fields not linked to the model (:func:`unlinked`)."""


def unlinked(default: Any = None) -> Any:
    """A contract field the model does not take as an argument (it reads it from ``module.contract``)."""
    return dataclasses.field(default=default, metadata={LINKED: False})


@dataclasses.dataclass(frozen=True, kw_only=True)
class DataContract:
    """The base of the data modules' contracts: what a data module's samples fix for the model.

    A task's contract derives from it with one typed field per value (keyword-only, so a misspelt name fails
    where the contract is built). Fields are linked to the model's arguments of their names unless marked
    :func:`unlinked`.

    Attributes:
        statistics: per-channel statistics of the training split, a task's own dataclass of named tensors
            (None: before the split is set up, or a task without data-dependent normalisation).
    """

    statistics: Any = unlinked(None)


def linked_fields(contract_class: type[DataContract]) -> tuple[str, ...]:
    """The fields of ``contract_class`` that are linked to the model (all but the :func:`unlinked`)."""
    return tuple(f.name for f in dataclasses.fields(contract_class) if f.metadata.get(LINKED, True))


def data_contract(datamodule: LightningDataModule, include_statistics: bool = True) -> DataContract | None:
    """The contract of ``datamodule``: its ``contract`` with (``include_statistics``) the training split's
    statistics from its ``training_statistics()`` where it has one; None for a data module that declares no
    ``contract_class``.

    Raises:
        InputError: the data module's contract does not build (a misspelt or missing field), in one line.
    """
    if not isinstance(getattr(type(datamodule), "contract_class", None), type):
        return None
    name = type(datamodule).__name__
    try:
        contract = datamodule.contract
    except TypeError as err:  # the dataclass refusing a keyword: a field misspelt or missing
        raise InputError(f"{name}.contract: {err}") from err
    if not isinstance(contract, DataContract):
        raise InputError(f"{name}.contract is a {type(contract).__name__}, not a DataContract")
    statistics = getattr(datamodule, "training_statistics", None)
    if include_statistics and callable(statistics):
        contract = dataclasses.replace(contract, statistics=statistics())
    return contract


LINK_PREFIX = "contract__"
"""The attribute prefix the links read a contract field through (:class:`ContractDataModule`)."""


class ContractDataModule(LightningDataModule):
    """A LightningDataModule with a typed contract (``contract_class``, ``contract``), whose linked fields
    also read as the attributes ``contract__<field>``: what LightningCLI's links read, so that a link of a
    field the chosen data module's contract does not have is skipped (jsonargparse skips a missing source
    attribute), and one of a field it has reads the contract, not an attribute of the data module."""

    def __getattr__(self, name: str) -> Any:
        if name.startswith(LINK_PREFIX):
            contract = data_contract(self, include_statistics=False)
            field = name[len(LINK_PREFIX) :]
            if contract is not None and field in linked_fields(type(contract)):
                return getattr(contract, field)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")


class SplitDataModule(ContractDataModule):
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
