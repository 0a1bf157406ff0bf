"""``sm predict`` output for EgoMusic dance estimation: every sampled dance written as files and listed.

For each predicted window (the data module's test split): ``<sample_id>_dance.npz`` (our motion format),
``.bvh``, ``.glb`` and ``.mp4`` with its ``.wav`` (the window's slice of its music), as ``sm dance`` writes
them (:func:`~.export.write_dance`), in ``predictions/`` of the logger's log_dir (``predictions_rank{r}/``
per process under DDP); each window's files are printed as they are written. With ``sm predict --rig RIG``
also ``<sample_id>_dance_rig.glb`` / ``.vrm`` / ``.bvh``: the dance on that character
(:mod:`~skeleton_mamba.tasks.training.prediction_rig`).
"""

from __future__ import annotations

from pathlib import Path

import torch
from lightning.pytorch import LightningModule, Trainer
from lightning.pytorch.callbacks import BasePredictionWriter
from lightning.pytorch.utilities import rank_zero_info

from skeleton_mamba.tasks.egodance.export import write_dance
from skeleton_mamba.tasks.training.prediction_rig import PredictionRig

__all__ = ["DancePredictionWriter"]


class DancePredictionWriter(BasePredictionWriter):
    """Writes the dances of :meth:`EgoDanceModule.predict_step` (module docstring).

    Args:
        output_dir: the folder (``None``: ``predictions/`` in the trainer's log_dir, else in its
            ``default_root_dir``).
        render: also write the mp4 with the music.
    """

    def __init__(self, output_dir: str | None = None, render: bool = True) -> None:
        super().__init__(write_interval="batch")
        self.output_dir = output_dir
        self.render = render
        self.written: list[Path] = []

    def folder(self, trainer: Trainer) -> Path:
        if self.output_dir is not None:
            return Path(self.output_dir)
        name = "predictions" if trainer.world_size == 1 else f"predictions_rank{trainer.global_rank}"
        return Path(trainer.log_dir or trainer.default_root_dir or ".") / name

    def on_predict_epoch_start(self, trainer: Trainer, pl_module: LightningModule) -> None:
        self.written = []

    def write_on_batch_end(
        self, trainer, pl_module, prediction, batch_indices, batch, batch_idx, dataloader_idx=0
    ) -> None:
        tokens = prediction["tokens"].detach().float().cpu()
        ids = prediction.get("sample_id") or [f"sample{batch_idx:04d}_{i}" for i in range(len(tokens))]
        starts = batch.get("music_start_s")
        for i, sample_id in enumerate(ids):
            start = float(starts[i]) if torch.is_tensor(starts) or isinstance(starts, list) else 0.0
            music = batch["music_path"][i] if "music_path" in batch else None
            files = write_dance(
                tokens[i],
                self.folder(trainer),
                f"{sample_id}_dance",
                music=music,
                music_start_s=start,
                fps=float(pl_module.hparams.fps),
                render=self.render,
                title=f"EMM prediction {sample_id}",
            )
            if (rig := PredictionRig.of(trainer)) is not None:  # sm predict --rig: on the character too
                files.rig = rig.write(files.npz, f"{sample_id}_dance")
            paths = [p for p in vars(files).values() if p is not None]
            self.written.extend(paths)
            rank_zero_info(f"sm predict: {sample_id} ({prediction['head_source']} head guidance)\n"
                           + "\n".join(files.lines()))  # fmt: skip

    def on_predict_epoch_end(self, trainer: Trainer, pl_module: LightningModule) -> None:
        dances = sum(p.suffix == ".npz" for p in self.written)
        rank_zero_info(f"sm predict: {dances} dances written to {self.folder(trainer)}")
