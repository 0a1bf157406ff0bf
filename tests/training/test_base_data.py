"""The shared data-module base: four loaders from one factory."""

from __future__ import annotations

import torch
from torch.utils.data import RandomSampler, SequentialSampler, TensorDataset

from skeleton_mamba.tasks.training.base_data import SplitDataModule


class _Numbers(SplitDataModule):
    def setup(self, stage: str) -> None:
        for k, split in enumerate(("train", "val", "test")):
            self.datasets[split] = TensorDataset(torch.arange(10 * k, 10 * k + 5))

    def loader_options(self, split: str) -> dict:
        return {"drop_last": split == "train"}


def test_loaders_read_their_split_shuffle_only_training_and_predict_the_test_split():
    data = _Numbers(batch_size=2, num_workers=0)
    data.setup("fit")
    loaders = {
        "train": data.train_dataloader(),
        "val": data.val_dataloader(),
        "test": data.test_dataloader(),
        "predict": data.predict_dataloader(),
    }
    assert isinstance(loaders["train"].sampler, RandomSampler)
    for name in ("val", "test", "predict"):
        assert isinstance(loaders[name].sampler, SequentialSampler)
    assert [len(loader) for loader in loaders.values()] == [2, 3, 3, 3]  # 5 items: drop_last for train only
    values = {name: torch.cat([b[0] for b in loader]).tolist() for name, loader in loaders.items()}
    assert len(set(values["train"])) == 4 and set(values["train"]) <= {0, 1, 2, 3, 4}
    assert values["val"] == [10, 11, 12, 13, 14]
    assert values["test"] == values["predict"] == [20, 21, 22, 23, 24]
    assert loaders["train"].batch_size == 2 and loaders["test"].num_workers == 0
