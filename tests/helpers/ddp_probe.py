"""A callback for the DDP tests: records which training samples each rank draws in each epoch.

``sm fit --trainer.callbacks+=ddp_probe.SampleProbe`` with ``tests/helpers/`` on ``PYTHONPATH`` and
``SM_PROBE_DIR`` set writes ``rank<R>-epoch<E>.json`` there: the indices of the training set that rank's
loader read during epoch E (the loader's workers are 0 in the recipes this is used with, so the dataset's
``__getitem__`` runs in the rank's own process).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from lightning.pytorch import Callback
from torch.utils.data import Dataset


class _Recording(Dataset):
    def __init__(self, dataset: Dataset) -> None:
        self.dataset = dataset
        self.seen: list[int] = []

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, index: int):
        self.seen.append(int(index))
        return self.dataset[index]


class SampleProbe(Callback):
    """Wraps the training set after the data module's setup; writes each epoch's indices per rank."""

    def setup(self, trainer, pl_module, stage: str) -> None:
        if stage == "fit":
            trainer.datamodule.datasets["train"] = _Recording(trainer.datamodule.datasets["train"])

    def on_train_epoch_end(self, trainer, pl_module) -> None:
        recording = trainer.datamodule.datasets["train"]
        name = f"rank{trainer.global_rank}-epoch{trainer.current_epoch}.json"
        record = {"world": trainer.world_size, "seen": recording.seen}
        (Path(os.environ["SM_PROBE_DIR"]) / name).write_text(json.dumps(record))
        recording.seen = []
