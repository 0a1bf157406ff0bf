"""Training the T2M evaluator here, for users without the official checkpoint (results NOT comparable).

Follows ``TextMotionMatchTrainer`` (``EricGuo5513/text-to-motion networks/trainers.py``): Hadsell
contrastive loss ``(1 - y) d^2 + y max(0, m - d)^2`` with margin m = 10 (``--negative_margin 10.0``),
positives the matched (text, motion) pairs (y = 0), negatives the batch's motions shifted by a random
offset (y = 1), Adam lr 1e-4. Deviation: the original loads a movement encoder pretrained as an
autoencoder (``Decomp_SP001_SM001_H512``) and keeps it fixed; here it is trained jointly. An evaluator
trained here gives scores that must be labelled as not comparable with published numbers
(``T2MEvaluator.comparable`` is False).

Batches come from :class:`~.evaluator_data.T2MEvaluatorDataModule`.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from lightning.pytorch import LightningModule

from skeleton_mamba.tasks.text2motion.evaluator import T2MEvaluator
from skeleton_mamba.tasks.text2motion.metrics import RPrecision

__all__ = ["contrastive_loss", "T2MEvaluatorModule"]


def contrastive_loss(a: torch.Tensor, b: torch.Tensor, label: torch.Tensor, margin: float) -> torch.Tensor:
    """Hadsell et al. (2006): mean of ``(1 - y) d^2 + y clamp(margin - d, 0)^2``, ``d = |a - b|`` per row."""
    distance = F.pairwise_distance(a, b, keepdim=True)
    label = label[:, None].to(distance.dtype)
    return torch.mean((1 - label) * distance**2 + label * torch.clamp(margin - distance, min=0.0) ** 2)


class T2MEvaluatorModule(LightningModule):
    """Trains :class:`~.evaluator.T2MEvaluator` by contrastive text-motion matching.

    Args:
        feature_dim: motion feature size (263).
        margin: negative margin (10).
        lr: Adam learning rate (1e-4).
    """

    def __init__(self, feature_dim: int = 263, margin: float = 10.0, lr: float = 1e-4) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.evaluator = T2MEvaluator(feature_dim, comparable=False)
        self.val_r_precision = RPrecision()

    def _embed(self, batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
        text = self.evaluator.embed_text(batch["word_embs"], batch["pos_onehot"], batch["cap_len"])
        motion = self.evaluator.embed_motion(batch["motion"], batch["length"])
        return text, motion

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        text, motion = self._embed(batch)
        b = text.shape[0]
        positive = contrastive_loss(text, motion, torch.zeros(b, device=self.device), self.hparams.margin)
        shift = int(torch.randint(0, max(b - 1, 1), ()))  # np.random.randint(0, batch_size - 1)
        shifted = motion[(torch.arange(b, device=self.device) + shift) % b]
        negative = contrastive_loss(text, shifted, torch.ones(b, device=self.device), self.hparams.margin)
        loss = positive + negative
        self.log_dict({"train/loss_pos": positive, "train/loss_neg": negative}, batch_size=b)
        self.log("train/loss", loss, prog_bar=True, batch_size=b)
        return loss

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        text, motion = self._embed(batch)
        self.val_r_precision.update(text, motion)

    def on_validation_epoch_end(self) -> None:
        if self.val_r_precision.count > 0:
            self.log_dict({f"val/{k}": v for k, v in self.val_r_precision.compute().items()}, prog_bar=True)
        self.val_r_precision.reset()

    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.Adam(self.evaluator.parameters(), lr=self.hparams.lr)
