"""T2M evaluation metrics ([T2M]) over evaluator embeddings, as torchmetrics metrics.

Definitions follow ``EricGuo5513/text-to-motion utils/metrics.py`` and ``final_evaluations.py`` (MDM
``eval/eval_humanml.py`` uses the same code):

- R-Precision top-k: in each group of 32 (text, motion) pairs, the 32 x 32 Euclidean distances between
  text and motion embeddings; a text scores a hit at k when its own motion is among the k nearest.
  Averaged over all texts; groups are consecutive (the caller shuffles), an incomplete last group is
  dropped (``drop_last``).
- MM-Dist ("Matching Score"): mean distance between matched text and motion embeddings, same groups.
- FID: ``|mu_g - mu_r|^2 + Tr(S_g + S_r - 2 (S_g S_r)^(1/2))`` over motion embeddings, covariances with
  ``np.cov`` (unbiased).
- Diversity: mean distance over ``times`` (300) random pairs, each side drawn without replacement.
- MultiModality: per text, ``times`` (10) random pairs among its generations (30), mean distance.
- Replications (20): report ``mean +- 1.96 std / sqrt(n)``, population std (:func:`confidence_interval`).
"""

from __future__ import annotations

from typing import Any

import torch
from torchmetrics import Metric
from torchmetrics.utilities import dim_zero_cat

from skeleton_mamba.tasks.motion.metrics.fid import frechet_distance

__all__ = [
    "R_PRECISION_BATCH",
    "top_k_hits",
    "confidence_interval",
    "diversity",
    "multimodality",
    "embedding_fid",
    "RPrecision",
    "EmbeddingFID",
    "Diversity",
    "MultiModality",
]

R_PRECISION_BATCH = 32


def top_k_hits(text: torch.Tensor, motion: torch.Tensor, top_k: int = 3) -> torch.Tensor:
    """Per text, whether its motion ranks within the k nearest: (N, D), (N, D) -> (N, top_k) bool.

    Column ``k - 1`` is the top-k hit (cumulative over ranks), as ``calculate_top_k``.
    """
    distances = torch.cdist(text.double(), motion.double())  # (N, N)
    order = distances.argsort(dim=1, stable=True)
    own = order == torch.arange(len(text), device=text.device)[:, None]
    return own[:, :top_k].cumsum(dim=1) > 0


def confidence_interval(values: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(mean, 1.96 * std / sqrt(n))`` over the first axis, population std (``get_metric_statistics``)."""
    values = values.double()
    return values.mean(0), 1.96 * values.std(0, correction=0) / values.shape[0] ** 0.5


def diversity(
    embeddings: torch.Tensor, times: int = 300, generator: torch.Generator | None = None
) -> torch.Tensor:
    """Mean distance between ``times`` random pairs of rows of (N, D) (each side without replacement)."""
    n = embeddings.shape[0]
    if n < times:
        raise ValueError(f"diversity needs at least {times} samples, got {n}")
    first = torch.randperm(n, generator=generator)[:times]
    second = torch.randperm(n, generator=generator)[:times]
    return (embeddings[first].double() - embeddings[second].double()).norm(dim=-1).mean()


def multimodality(
    embeddings: torch.Tensor, times: int = 10, generator: torch.Generator | None = None
) -> torch.Tensor:
    """Mean distance between ``times`` random pairs of generations per text: (N_text, N_gen, D) -> scalar."""
    per_text = embeddings.shape[1]
    if per_text < times:
        raise ValueError(f"multimodality needs at least {times} generations per text, got {per_text}")
    first = torch.randperm(per_text, generator=generator)[:times]
    second = torch.randperm(per_text, generator=generator)[:times]
    return (embeddings[:, first].double() - embeddings[:, second].double()).norm(dim=-1).mean()


def embedding_fid(real: torch.Tensor, generated: torch.Tensor) -> torch.Tensor:
    """Frechet distance between Gaussians fitted to (N, D) real and (M, D) generated embeddings."""
    real, generated = real.double(), generated.double()
    cov_real, cov_generated = (torch.atleast_2d(torch.cov(x.T)) for x in (real, generated))
    return frechet_distance(generated.mean(0), cov_generated, real.mean(0), cov_real)


class RPrecision(Metric):
    """R-Precision top-1..k and MM-Dist over groups of ``batch_size`` (32) pairs.

    ``update(text, motion)`` takes (N, D) embeddings in matching order; consecutive groups of
    ``batch_size`` are scored, the last incomplete group of each update is dropped. ``compute()``
    returns ``{"top1": ..., "top2": ..., "top3": ..., "mm_dist": ...}``.
    """

    is_differentiable = False
    higher_is_better = True
    full_state_update = False

    def __init__(self, top_k: int = 3, batch_size: int = R_PRECISION_BATCH, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.top_k = top_k
        self.batch_size = batch_size
        self.add_state("hits", default=torch.zeros(top_k, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("matched_distance", default=torch.zeros((), dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("count", default=torch.zeros((), dtype=torch.float64), dist_reduce_fx="sum")

    def update(self, text: torch.Tensor, motion: torch.Tensor) -> None:
        if text.shape != motion.shape or text.ndim != 2:
            shapes = f"{tuple(text.shape)} and {tuple(motion.shape)}"
            raise ValueError(f"expected matching (N, D) text and motion embeddings, got {shapes}")
        for start in range(0, len(text) - self.batch_size + 1, self.batch_size):
            t, m = text[start : start + self.batch_size], motion[start : start + self.batch_size]
            self.hits += top_k_hits(t, m, self.top_k).sum(0).double()
            self.matched_distance += (t.double() - m.double()).norm(dim=-1).sum()
            self.count += self.batch_size

    def compute(self) -> dict[str, torch.Tensor]:
        if self.count == 0:
            raise RuntimeError(f"RPrecision: no complete group of {self.batch_size} pairs was added")
        result = {f"top{k + 1}": self.hits[k] / self.count for k in range(self.top_k)}
        result["mm_dist"] = self.matched_distance / self.count
        return result


class _EmbeddingStore(Metric):
    is_differentiable = False
    full_state_update = False

    def _cat(self, state: list[torch.Tensor] | torch.Tensor, what: str) -> torch.Tensor:
        if isinstance(state, list) and not state:
            raise RuntimeError(f"{type(self).__name__}: no {what} embeddings were added")
        return dim_zero_cat(state).double()


class EmbeddingFID(_EmbeddingStore):
    """FID between real and generated motion embeddings: ``update(embeddings, real)``."""

    higher_is_better = False

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.add_state("real_embeddings", default=[], dist_reduce_fx="cat")
        self.add_state("generated_embeddings", default=[], dist_reduce_fx="cat")

    def update(self, embeddings: torch.Tensor, real: bool) -> None:
        (self.real_embeddings if real else self.generated_embeddings).append(embeddings.double())

    def compute(self) -> torch.Tensor:
        return embedding_fid(
            self._cat(self.real_embeddings, "real"), self._cat(self.generated_embeddings, "generated")
        )


class Diversity(_EmbeddingStore):
    """Diversity of motion embeddings over ``times`` (300) random pairs; ``seed`` fixes the draw."""

    higher_is_better = True

    def __init__(self, times: int = 300, seed: int | None = None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.times = times
        self.seed = seed
        self.add_state("embeddings", default=[], dist_reduce_fx="cat")

    def update(self, embeddings: torch.Tensor) -> None:
        self.embeddings.append(embeddings.double())

    def compute(self) -> torch.Tensor:
        generator = None if self.seed is None else torch.Generator().manual_seed(self.seed)
        return diversity(self._cat(self.embeddings, "motion").cpu(), self.times, generator)


class MultiModality(_EmbeddingStore):
    """MultiModality: ``update((N_text, N_gen, D))`` generations per text; ``times`` (10) pairs per text."""

    higher_is_better = True

    def __init__(self, times: int = 10, seed: int | None = None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.times = times
        self.seed = seed
        self.add_state("embeddings", default=[], dist_reduce_fx="cat")

    def update(self, embeddings: torch.Tensor) -> None:
        if embeddings.ndim != 3:
            raise ValueError(f"expected (N_text, N_gen, D) embeddings, got {tuple(embeddings.shape)}")
        self.embeddings.append(embeddings.double())

    def compute(self) -> torch.Tensor:
        generator = None if self.seed is None else torch.Generator().manual_seed(self.seed)
        return multimodality(self._cat(self.embeddings, "generation").cpu(), self.times, generator)
