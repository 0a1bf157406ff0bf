"""``sm predict`` output for action recognition: one CSV row per sample.

The columns are ``sample`` (the annotation's ``frame_dir``), ``label`` (the annotated class, -1 when
unknown), ``predicted``, ``predicted_name``, ``probability`` (of the predicted class) and ``top5``
(``class:probability`` pairs, best first, ``;``-separated). The file is ``predictions.csv`` in the
logger's log_dir (``predictions_rank{r}.csv`` per process under DDP, each holding its own samples).
"""

from __future__ import annotations

import csv
from pathlib import Path

from lightning.pytorch import LightningModule, Trainer
from lightning.pytorch.callbacks import BasePredictionWriter
from lightning.pytorch.utilities import rank_zero_info

from skeleton_mamba.io.atomic import atomic_open

__all__ = ["PredictionCSVWriter"]

COLUMNS = ("sample", "label", "predicted", "predicted_name", "probability", "top5")


class PredictionCSVWriter(BasePredictionWriter):
    """Writes the class probabilities of ``predict_step`` (B, K) as CSV rows.

    Args:
        class_names: optional class names (index = class id) for the ``predicted_name`` and
            ``top5`` columns.
        output_dir: folder of the CSV (``None``: the trainer's log_dir, else the working directory).
    """

    def __init__(self, class_names: list[str] | None = None, output_dir: str | None = None) -> None:
        super().__init__(write_interval="batch")
        self.class_names = class_names
        self.output_dir = output_dir
        self._rows: list[tuple] = []

    def _name(self, index: int) -> str:
        names = self.class_names
        return names[index] if names is not None and index < len(names) else str(index)

    def on_predict_epoch_start(self, trainer: Trainer, pl_module: LightningModule) -> None:
        self._rows = []

    def write_on_batch_end(
        self, trainer, pl_module, prediction, batch_indices, batch, batch_idx, dataloader_idx=0
    ) -> None:
        prob = prediction.detach().float().cpu()
        dataset = trainer.predict_dataloaders
        dataset = (dataset[dataloader_idx] if isinstance(dataset, list | tuple) else dataset).dataset
        annotations = getattr(dataset, "annotations", None)
        labels = batch[1].tolist() if isinstance(batch, list | tuple) and len(batch) > 1 else None
        top = prob.topk(min(5, prob.shape[-1]), dim=-1)
        for row in range(prob.shape[0]):
            index = batch_indices[row] if batch_indices is not None else None
            sample = (
                annotations[index].get("frame_dir", str(index))
                if annotations is not None and index is not None
                else str(index if index is not None else row)
            )
            predicted = int(top.indices[row, 0])
            top5 = ";".join(
                f"{self._name(int(c))}:{float(p):.4f}" for p, c in zip(top.values[row], top.indices[row])
            )
            label = int(labels[row]) if labels is not None else -1
            probability = f"{prob[row, predicted]:.6f}"
            self._rows.append((sample, label, predicted, self._name(predicted), probability, top5))

    def on_predict_epoch_end(self, trainer: Trainer, pl_module: LightningModule) -> None:
        folder = Path(self.output_dir or trainer.log_dir or ".")
        folder.mkdir(parents=True, exist_ok=True)
        name = "predictions.csv" if trainer.world_size == 1 else f"predictions_rank{trainer.global_rank}.csv"
        path = folder / name
        with atomic_open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(COLUMNS)
            writer.writerows(self._rows)
        rank_zero_info(f"{len(self._rows)} predictions written to {path}")
        self._rows = []
