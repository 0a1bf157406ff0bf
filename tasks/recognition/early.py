"""Online (per-frame) class probabilities of a causal recognizer and the early-recognition curve.

With a causal backbone (``SkeletonMambaConfig(causal=True)``), the features of frame s depend on
frames <= s only, so restricting the recognizer's global average pooling to the frames seen so far
gives a class distribution after every frame t that uses nothing after t::

    p_t = softmax(W * mean_{bodies present in frames <= t} mean_{s <= t, joints} f_s + b)

At the last frame this is exactly the clip's prediction (:class:`ActionRecognizer`). The
early-recognition curve is the top-1 accuracy of ``p_t`` at the frame where a fraction ``r`` of the
clip has been observed, ``t = ceil(r * T) - 1``, for r = 0.1, 0.2, ..., 1.0 (test clips' probabilities
averaged per sample, as the clip-level evaluation does).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import torch
from einops import rearrange
from torchmetrics import Metric

from skeleton_mamba.tasks.recognition.model import ActionRecognizer, pool_bodies

__all__ = ["EarlyRecognitionCurve", "FRACTIONS", "online_probabilities", "save_early_curve"]

FRACTIONS = tuple(round(0.1 * k, 1) for k in range(1, 11))


def online_probabilities(model: ActionRecognizer, x: torch.Tensor) -> torch.Tensor:
    """Per-frame class probabilities (B, T, K) of keypoints (B, M, T, J, C), each from frames <= t."""
    if not model.backbone.config.causal:
        raise ValueError("online recognition needs a causal backbone (backbone.causal: true)")
    b, t = x.shape[0], x.shape[2]
    features = model.backbone(rearrange(model.normalize(x), "b m t j c -> (b m) t j c")).mean(
        dim=2
    )  # (B*M, T, D)
    count = torch.arange(1, t + 1, device=x.device, dtype=features.dtype)[:, None]
    running = rearrange(features.cumsum(dim=1) / count, "(b m) t d -> b m t d", b=b)
    present = x.flatten(3).ne(0).any(dim=-1).cummax(dim=2).values  # (B, M, T): seen up to t
    return model.head(pool_bodies(running, present)).softmax(dim=-1)


class EarlyRecognitionCurve(Metric):
    """Top-1 accuracy against the observed fraction of the clip (see the module docstring).

    ``update(prob (B, T, K), label (B,))``; ``compute()`` -> (len(FRACTIONS),) accuracies.
    """

    full_state_update = False

    def __init__(self, fractions: tuple[float, ...] = FRACTIONS) -> None:
        super().__init__()
        self.fractions = fractions
        self.add_state("correct", default=torch.zeros(len(fractions)), dist_reduce_fx="sum")
        self.add_state("total", default=torch.tensor(0.0), dist_reduce_fx="sum")

    def update(self, prob: torch.Tensor, label: torch.Tensor) -> None:
        frames = prob.shape[1]
        index = torch.tensor([max(0, math.ceil(r * frames) - 1) for r in self.fractions], device=prob.device)
        top1 = prob[:, index].argmax(dim=-1)  # (B, F)
        self.correct += (top1 == label[:, None]).sum(dim=0).to(self.correct)
        self.total += label.numel()

    def compute(self) -> torch.Tensor:
        return self.correct / self.total.clamp_min(1)


def save_early_curve(
    accuracy: torch.Tensor, path: str | Path, fractions: tuple[float, ...] = FRACTIONS
) -> Path:
    """Write the curve as ``path`` (PNG) and ``path.csv`` (fraction, top1); returns the PNG path."""
    import matplotlib  # lazy: matplotlib only for this figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib only for this figure

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    values = [float(v) for v in accuracy]
    with open(path.with_suffix(".csv"), "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(["observed_fraction", "top1"])
        writer.writerows(zip(fractions, values))
    fig, ax = plt.subplots(figsize=(5, 3.5), dpi=120)
    ax.plot([100 * r for r in fractions], [100 * v for v in values], marker="o")
    ax.set(xlabel="observed part of the clip (%)", ylabel="top-1 accuracy (%)", title="Early recognition",
           xlim=(0, 102), ylim=(0, 102))  # fmt: skip
    ax.grid(alpha=0.3)
    fig.tight_layout()
    tmp = path.with_name(f".{path.name}.tmp.png")
    fig.savefig(tmp)
    plt.close(fig)
    tmp.replace(path)
    return path
