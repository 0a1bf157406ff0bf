"""LightningModule for skeleton action recognition: cross-entropy, SGD + cosine, top-k accuracy.

Training schedule defaults follow the reference toolkits (PYSKL ST-GCN++/CTR-GCN NTU configs,
mmaction2 ``stgcnpp_8xb16``): SGD, momentum 0.9, Nesterov, weight decay 5e-4, learning rate 0.1
for a global batch of 128, cosine annealing to 0 per optimizer step.

Learning-rate scaling (linear rule, PYSKL maintainer in pyskl #51): ``batch_size`` is the
per-device batch of the data module (linked), and the optimizer uses::

    lr_used = lr * global_batch / base_batch_size,
    global_batch = batch_size * trainer.world_size * trainer.accumulate_grad_batches

so ``lr: 0.1, base_batch_size: 128`` gives 0.1 for 1 device x 128, 8 devices x 16, or 2 devices x 64,
and 0.2 for 2 devices x 128. The value used is logged as ``lr`` and printed at fit start.

Evaluation follows PYSKL (``average_clips='prob'``): a sample may carry several clips
(B, N, M, T, J, C); the softmax probabilities of its clips are averaged. Metrics are torchmetrics
top-1 / top-5 accuracy (micro) and, at test time, mean class accuracy and the confusion matrix,
saved as ``confusion_matrix.png`` and ``.csv`` in the logger's log_dir, and every sample's class scores
(the clip-averaged probabilities and logits, with the sample names in the split's order) as ``scores.npz``
there (:mod:`.scores`; ``sm ensemble`` adds the scores of several streams, as [PYSKL] does). ``sm predict``
writes ``predictions.csv`` there (:mod:`.prediction_writer`).
"""

from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F
from lightning.pytorch.utilities import rank_zero_info, rank_zero_warn
from torchmetrics import MetricCollection
from torchmetrics.classification import MulticlassAccuracy, MulticlassConfusionMatrix

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.errors import CheckpointError
from skeleton_mamba.tasks.recognition.confusion import save_confusion_matrix
from skeleton_mamba.tasks.recognition.early import (
    FRACTIONS,
    EarlyRecognitionCurve,
    online_probabilities,
    save_early_curve,
)
from skeleton_mamba.tasks.recognition.model import ActionRecognizer
from skeleton_mamba.tasks.recognition.prediction_writer import PredictionCSVWriter
from skeleton_mamba.tasks.recognition.scores import SCORES_FILE, save_scores
from skeleton_mamba.tasks.training.backbone_config import derived_backbone
from skeleton_mamba.tasks.training.base_module import BackboneModule, attached_trainer

__all__ = ["ActionRecognitionModule"]


class ActionRecognitionModule(BackboneModule):
    """Skeleton Mamba action recognizer.

    Args:
        backbone: the backbone configuration (recipes include ``backbones/skeleton_mamba.yaml``).
            Its ``skeleton`` and ``in_channels`` fields are replaced by the linked values below.
        num_classes: K. Linked from the data module (not user-settable under ``sm``).
        skeleton: skeleton name. Linked from the data module.
        in_channels: per-joint input channels. Linked from the data module.
        batch_size: per-device batch size. Linked from the data module; used for the LR scaling.
        dropout: dropout before the linear classifier.
        input_norm: batch-normalise the input channels first (:class:`.model.ActionRecognizer`; for the
            bone and motion streams).
        label_smoothing: label smoothing of the cross-entropy.
        lr: SGD learning rate for a global batch of ``base_batch_size`` (scaled linearly).
        base_batch_size: the global batch that ``lr`` refers to.
        momentum: SGD momentum.
        nesterov: Nesterov momentum.
        weight_decay: L2 weight decay (all parameters, as in PYSKL/mmcv).
        class_names: optional names for the confusion-matrix axes.
    """

    def __init__(
        self,
        backbone: SkeletonMambaConfig | None = None,
        num_classes: int = 60,
        skeleton: str = "ntu25",
        in_channels: int = 3,
        batch_size: int = 128,
        dropout: float = 0.0,
        input_norm: bool = False,
        label_smoothing: float = 0.0,
        lr: float = 0.1,
        base_batch_size: int = 128,
        momentum: float = 0.9,
        nesterov: bool = True,
        weight_decay: float = 5e-4,
        class_names: list[str] | None = None,
    ) -> None:
        super().__init__()
        config = self.save_backbone_hyperparameters(backbone)
        config = derived_backbone(config, "the data", skeleton=skeleton, in_channels=in_channels)
        self.model = ActionRecognizer(config, num_classes=num_classes, dropout=dropout, input_norm=input_norm)
        top_k = {"top1": MulticlassAccuracy(num_classes, top_k=1, average="micro")}
        if num_classes > 5:
            top_k["top5"] = MulticlassAccuracy(num_classes, top_k=5, average="micro")
        metrics = MetricCollection(top_k)
        self.train_metrics = metrics.clone(prefix="train/")
        self.val_metrics = metrics.clone(prefix="val/")
        self.test_metrics = metrics.clone(prefix="test/")
        self.test_mean_class_accuracy = MulticlassAccuracy(num_classes, average="macro")
        self.test_confusion = MulticlassConfusionMatrix(num_classes)
        # Causal backbones: the early-recognition curve from per-frame probabilities (.early).
        self.test_early = EarlyRecognitionCurve() if self.model.backbone.config.causal else None
        self._test_scores: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []

    def clip_logits(self, keypoint: torch.Tensor) -> torch.Tensor:
        """Class logits (B, N, K) of every clip of keypoints (B, N, M, T, J, C)."""
        b, n = keypoint.shape[:2]
        return self.model(keypoint.flatten(0, 1)).unflatten(0, (b, n))

    @staticmethod
    def average_probabilities(logits: torch.Tensor) -> torch.Tensor:
        """Clip logits (B, N, K) -> class probabilities (B, K): the softmax of each clip, averaged."""
        # fp32 probabilities also under bf16-mixed (bf16's 8-bit mantissa: sums off by 2e-3)
        return logits.softmax(dim=-1, dtype=torch.promote_types(logits.dtype, torch.float32)).mean(dim=1)

    def forward(self, keypoint: torch.Tensor) -> torch.Tensor:
        """Class probabilities (B, K), averaged over clips, for keypoints (B, N, M, T, J, C)."""
        return self.average_probabilities(self.clip_logits(keypoint))

    def training_step(self, batch: tuple[torch.Tensor, torch.Tensor], batch_idx: int) -> torch.Tensor:
        keypoint, label = batch
        logits = self.model(keypoint.flatten(0, 1))  # training samples carry one clip each
        label = label.repeat_interleave(keypoint.shape[1])
        loss = F.cross_entropy(logits, label, label_smoothing=self.hparams.label_smoothing)
        self.train_metrics.update(logits, label)
        self.log("train/loss", loss, prog_bar=True, batch_size=label.numel())
        self.log_dict(self.train_metrics, on_step=False, on_epoch=True, batch_size=label.numel())
        return loss

    def _evaluate(
        self, prob: torch.Tensor, label: torch.Tensor, metrics: MetricCollection, stage: str
    ) -> None:
        loss = F.nll_loss(prob.clamp_min(1e-12).log(), label)
        metrics.update(prob, label)
        self.log(f"{stage}/loss", loss, batch_size=label.numel(), sync_dist=True)
        self.log_dict(metrics, prog_bar=stage == "val", batch_size=label.numel())

    def validation_step(self, batch, batch_idx: int) -> None:
        self._evaluate(self(batch[0]), batch[1], self.val_metrics, "val")

    def on_test_epoch_start(self) -> None:
        self._test_scores = []

    def test_step(self, batch, batch_idx: int) -> None:
        logits = self.clip_logits(batch[0])
        prob = self.average_probabilities(logits)
        self._evaluate(prob, batch[1], self.test_metrics, "test")
        self._test_scores.append((prob.float().cpu(), logits.float().mean(dim=1).cpu(), batch[1].cpu()))
        self.test_mean_class_accuracy.update(prob, batch[1])
        self.test_confusion.update(prob, batch[1])
        self.log("test/mean_class_accuracy", self.test_mean_class_accuracy, batch_size=batch[1].numel())
        if self.test_early is not None:
            keypoint, label = batch
            online = online_probabilities(self.model, keypoint.flatten(0, 1))  # (B*N, T, K)
            self.test_early.update(online.unflatten(0, keypoint.shape[:2]).mean(dim=1), label)

    def predict_step(self, batch, batch_idx: int) -> torch.Tensor:
        """Class probabilities (B, K)."""
        keypoint = batch[0] if isinstance(batch, list | tuple) else batch
        return self(keypoint)

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        """Refuse a checkpoint trained on another input stream than the recipe's data (``feats``: the same
        channel count, so nothing else would notice a bone model tested on joints)."""
        super().on_load_checkpoint(checkpoint)
        trainer = attached_trainer(self)
        current = getattr(getattr(trainer, "datamodule", None), "feats", None)
        saved = checkpoint.get("datamodule_hyper_parameters")
        if current is None or not isinstance(saved, dict) or "skeleton" not in saved:
            return  # no recognition data module on either side
        trained = tuple(saved.get("feats") or ("j",))  # checkpoints from before the option: joints
        if trained != tuple(current):
            raise CheckpointError(
                f"the checkpoint was trained on feats {list(trained)}, the recipe's data gives "
                f"{list(current)}: add --data.init_args.feats '[{', '.join(trained)}]' "
                "(or use that stream's recipe)"
            )

    def configure_callbacks(self) -> list:
        """``sm predict`` writes ``predictions.csv`` to the log dir (:class:`PredictionCSVWriter`)."""
        return [PredictionCSVWriter(self.hparams.class_names)]

    def on_test_epoch_end(self) -> None:
        matrix = self.test_confusion.compute()  # synchronized over processes
        self.test_confusion.reset()
        log_dir = self.trainer.log_dir
        if self.trainer.is_global_zero and log_dir is not None:
            path = save_confusion_matrix(
                matrix.cpu(), Path(log_dir) / "confusion_matrix.png", self.hparams.class_names
            )
            rank_zero_info(f"confusion matrix saved to {path} (and {path.with_suffix('.csv').name})")
        self._save_test_scores(log_dir)
        if self.test_early is not None:
            self._log_early_curve(log_dir)

    def _save_test_scores(self, log_dir: str | None) -> None:
        """Write every test sample's scores, named, in the split's order, to ``scores.npz`` (:mod:`.scores`).

        Under DDP each rank scored its share of the split (the data module's sampler repeats no sample):
        the rows are gathered with their positions in the split and rank 0 writes one file in split order.
        """
        rows, self._test_scores = self._test_scores, []
        trainer = self.trainer
        loader = trainer.test_dataloaders
        loader = loader[0] if isinstance(loader, list | tuple) else loader
        names = getattr(getattr(loader, "dataset", None), "sample_names", None)
        k = self.hparams.num_classes
        empty = (torch.zeros(0, k), torch.zeros(0, k), torch.zeros(0, dtype=torch.long))
        prob, logit, label = (torch.cat(column) for column in zip(*(rows or [empty]), strict=True))
        position = torch.as_tensor(list(loader.sampler), dtype=torch.long)[: len(label)]
        if trainer.world_size > 1:
            prob, logit, label, position = self._gather_rows(prob, logit, label, position)
        if not trainer.is_global_zero or log_dir is None or not len(label):
            return
        if names is None or sorted(position.tolist()) != list(range(len(names))):
            rank_zero_warn(
                f"{SCORES_FILE} not written: the test loader's {len(label)} scored rows do not cover its "
                f"split once each ({len(names or ())} samples); sm ensemble reads it"
            )
            return
        order = torch.argsort(position)
        datamodule = getattr(trainer, "datamodule", None)
        path = save_scores(
            Path(log_dir) / SCORES_FILE,
            names,
            label[order].numpy(),
            prob[order].numpy(),
            logit[order].numpy(),
            split=str(getattr(datamodule, "splits", {}).get("test", "")),
            source=str(getattr(datamodule, "ann_file", "")),
            feats=tuple(getattr(datamodule, "feats", ())),
            checkpoint=str(trainer.ckpt_path or ""),
            class_names=self.hparams.class_names,
        )
        rank_zero_info(f"{len(label)} samples' class scores saved to {path} (sm ensemble adds runs' scores)")

    def _gather_rows(self, *columns: torch.Tensor) -> list[torch.Tensor]:
        """Every rank's rows of ``columns`` (n_rank, ...) concatenated in rank order (ranks may hold
        different counts: padded to the largest for the collective, then cut back)."""
        count = columns[0].shape[0]
        counts = self.all_gather(torch.tensor(count, device=self.device)).reshape(-1).tolist()
        most = max(counts)
        out = []
        for column in columns:
            padded = column.new_zeros(most, *column.shape[1:])
            padded[:count] = column
            gathered = self.all_gather(padded.to(self.device)).cpu()  # (world, most, ...)
            out.append(torch.cat([gathered[r, :n] for r, n in enumerate(counts)]))
        return out

    def _log_early_curve(self, log_dir: str | None) -> None:
        """Log top-1 at each observed fraction, print the curve and save it as a PNG + CSV."""
        accuracy = self.test_early.compute()
        self.test_early.reset()
        for fraction, value in zip(self.test_early.fractions, accuracy.tolist()):
            self.log(f"test/early_top1_at_{int(round(100 * fraction))}", value)
        pairs = zip(FRACTIONS, accuracy.tolist())
        rows = "  ".join(f"{int(round(100 * r))}%: {100 * v:.1f}" for r, v in pairs)
        rank_zero_info(f"early recognition, top-1 (%) against the observed part of the clip: {rows}")
        if self.trainer.is_global_zero and log_dir is not None:
            path = save_early_curve(accuracy.cpu(), Path(log_dir) / "early_recognition.png")
            rank_zero_info(f"early-recognition curve saved to {path} (and {path.with_suffix('.csv').name})")

    def effective_lr(self) -> float:
        """``lr * global_batch / base_batch_size`` (see the module docstring)."""
        trainer = attached_trainer(self)
        world = trainer.world_size if trainer is not None else 1
        accumulate = trainer.accumulate_grad_batches if trainer is not None else 1
        global_batch = self.hparams.batch_size * world * accumulate
        return self.hparams.lr * global_batch / self.hparams.base_batch_size

    def configure_optimizers(self):
        lr = self.effective_lr()
        rank_zero_info(
            f"SGD learning rate {lr:g} = lr {self.hparams.lr:g} x global batch / "
            f"{self.hparams.base_batch_size}"
        )
        optimizer = torch.optim.SGD(
            self.parameters(),
            lr=lr,
            momentum=self.hparams.momentum,
            nesterov=self.hparams.nesterov,
            weight_decay=self.hparams.weight_decay,
        )
        total_steps = max(int(self.trainer.estimated_stepping_batches), 1)
        scheduler = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=total_steps, eta_min=0.0)
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "step"}}
