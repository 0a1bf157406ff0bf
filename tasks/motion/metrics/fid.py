"""FID_k / FID_g and Div_k / Div_g of generated dance, with the reference normalisation protocol.

Protocol (liruilong940607/mint tools/calculate_fid_scores.py; lisiyao21/Bailando utils/metrics_new.py):

1. One 72-d kinetic (:func:`kinetic_features`) or 32-d geometric (:func:`geometric_features`) vector per
   sequence, for the real (reference) set and the generated set.
2. Both sets are standardised with the **real** statistics: ``x~ = (x - mu_real) / (sigma_real + 1e-10)``
   (``sigma`` = population standard deviation, ``np.std``).
3. ``FID = |mu_g - mu_r|^2 + Tr(S_g + S_r - 2 (S_g S_r)^(1/2))`` with ``np.cov(rowvar=False)`` covariances.
4. ``Div = 2 / (n (n - 1)) sum_{i<j} |f_i - f_j|`` over the normalised *generated* features.

Which frames to feed is the caller's choice: FACT scores generated frames ``120:1320`` (after the seed),
Bailando the first 1200 frames with the frame-0 root subtracted from every joint of both sets
(``zero_start=True`` here). Both codes use all AIST++ sequences (minus the ignore list), full length, as
the real set.

The trace term uses ``Tr((S_g S_r)^(1/2)) = sum sqrt(eig(S_r^(1/2) S_g S_r^(1/2)))``, a symmetric
eigenproblem that stays exact when a covariance is singular (40 sequences in 72 dimensions), where
``scipy.linalg.sqrtm`` of the product needs FACT's ``1e-6`` diagonal fallback.

The metrics keep every per-sequence feature vector (72 or 32 floats) as ``"cat"`` states, so the
normalisation statistics are exact over all processes; ``reset_real_features=False`` keeps the reference
set across ``reset()`` like torchmetrics' ``FrechetInceptionDistance``.
"""

from __future__ import annotations

from typing import Any, Literal

import torch
from torchmetrics import Metric
from torchmetrics.utilities import dim_zero_cat

from skeleton_mamba.tasks.motion.metrics.common import Positions, as_sequences
from skeleton_mamba.tasks.motion.metrics.geometric import geometric_features
from skeleton_mamba.tasks.motion.metrics.kinetic import kinetic_features

__all__ = [
    "FrechetMotionDistance",
    "MotionDiversity",
    "average_pairwise_distance",
    "frechet_distance",
    "motion_features",
    "normalise_by_reference",
]

FeatureKind = Literal["kinetic", "geometric"]
_DIMS = {"kinetic": 72, "geometric": 32}


def motion_features(
    positions: Positions,
    feature: FeatureKind = "kinetic",
    fps: float = 60.0,
    zero_start: bool = False,
    published_acceleration_bug: bool = True,
) -> torch.Tensor:
    """One feature vector per sequence: ``(B, 72)`` kinetic or ``(B, 32)`` geometric, float64.

    Args:
        positions: ``(B, T, 24, 3)`` y-up SMPL-24 joints or a list of ``(T_i, 24, 3)`` sequences.
        feature: ``"kinetic"`` or ``"geometric"``.
        fps: frame rate for the kinetic feature (AIST++ metrics: 60).
        zero_start: subtract the frame-0 root position from every joint (Bailando's protocol).
        published_acceleration_bug: kinetic EE quirk of the released code (see ``kinetic.py``).

    Examples:
        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> features = motion_features(torch.randn(2, 10, 24, 3), "kinetic")
        >>> features.shape, features.dtype
        (torch.Size([2, 72]), torch.float64)
        >>> motion_features([torch.randn(10, 24, 3)], "geometric").shape
        torch.Size([1, 32])
    """
    if feature not in _DIMS:
        raise ValueError(f"feature must be 'kinetic' or 'geometric', got {feature!r}")
    rows = []
    for seq in as_sequences(positions, min_frames=3, joints=24):
        if zero_start:
            seq = seq - seq[:1, :1, :]
        if feature == "kinetic":
            rows.append(kinetic_features(seq, fps=fps, published_acceleration_bug=published_acceleration_bug))
        else:
            rows.append(geometric_features(seq))
    return torch.stack(rows)


def normalise_by_reference(real: torch.Tensor, *others: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Standardise ``real`` and ``others`` with the real set's mean and population std (+1e-10).

    Examples:
        >>> import torch
        >>> real, other = normalise_by_reference(torch.tensor([[0.0], [2.0]]), torch.tensor([[3.0]]))
        >>> real.flatten().tolist(), other.flatten().tolist()
        ([-1.0, 1.0], [2.0])
    """
    mean = real.mean(0)
    std = real.std(0, correction=0) + 1e-10
    return tuple((x - mean) / std for x in (real, *others))


def frechet_distance(
    mu1: torch.Tensor, sigma1: torch.Tensor, mu2: torch.Tensor, sigma2: torch.Tensor
) -> torch.Tensor:
    """Frechet distance between ``N(mu1, sigma1)`` and ``N(mu2, sigma2)`` (float64 scalar).

    Examples:
        Two Gaussians with the same covariance, their means 5 apart:

        >>> import torch
        >>> mu, eye = torch.zeros(2), torch.eye(2)
        >>> round(float(frechet_distance(mu, eye, mu + torch.tensor([3.0, 4.0]), eye)), 6)
        25.0
    """
    mu1, mu2, sigma1, sigma2 = (x.to(torch.float64) for x in (mu1, mu2, sigma1, sigma2))
    w, v = torch.linalg.eigh(sigma2)
    sqrt2 = (v * w.clamp(min=0).sqrt()) @ v.T  # S2^(1/2)
    inner = sqrt2 @ sigma1 @ sqrt2
    trace_sqrt = torch.linalg.eigvalsh((inner + inner.T) / 2).clamp(min=0).sqrt().sum()
    return (mu1 - mu2).square().sum() + sigma1.trace() + sigma2.trace() - 2 * trace_sqrt


def average_pairwise_distance(features: torch.Tensor) -> torch.Tensor:
    """Mean Euclidean distance over all unordered pairs of rows of ``features`` ``(n, D)``, ``n >= 2``.

    Examples:
        >>> import torch
        >>> points = torch.tensor([[0.0, 0.0], [3.0, 4.0], [6.0, 8.0]])  # pairwise distances 5, 10, 5
        >>> round(float(average_pairwise_distance(points)), 4)
        6.6667
    """
    if features.shape[0] < 2:
        raise ValueError(f"diversity needs at least 2 samples, got {features.shape[0]}")
    return torch.pdist(features.to(torch.float64)).mean()


class _ReferenceNormalisedMetric(Metric):
    """Base: stores per-sequence features of a real and a generated set (``update(positions, real)``)."""

    is_differentiable = False
    full_state_update = False

    def __init__(
        self,
        feature: FeatureKind = "kinetic",
        fps: float = 60.0,
        zero_start: bool = False,
        published_acceleration_bug: bool = True,
        reset_real_features: bool = True,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        if feature not in _DIMS:
            raise ValueError(f"feature must be 'kinetic' or 'geometric', got {feature!r}")
        self.feature = feature
        self.fps = fps
        self.zero_start = zero_start
        self.published_acceleration_bug = published_acceleration_bug
        self.reset_real_features = reset_real_features
        self.add_state("real_features", default=[], dist_reduce_fx="cat")
        self.add_state("fake_features", default=[], dist_reduce_fx="cat")

    def update(
        self, positions: Positions | None = None, real: bool = False, features: torch.Tensor | None = None
    ) -> None:
        """Add sequences to the real or the generated set.

        Args:
            positions: ``(B, T, 24, 3)`` y-up joints or a list of ``(T_i, 24, 3)`` sequences.
            real: ``True`` for the reference set.
            features: instead of ``positions``, precomputed ``(B, 72)`` / ``(B, 32)`` feature vectors.
        """
        if (positions is None) == (features is None):
            raise ValueError("pass exactly one of positions or features")
        if features is None:
            features = motion_features(
                positions, self.feature, self.fps, self.zero_start, self.published_acceleration_bug
            )
        elif features.ndim != 2 or features.shape[1] != _DIMS[self.feature]:
            raise ValueError(
                f"expected (B, {_DIMS[self.feature]}) {self.feature} features, got {tuple(features.shape)}"
            )
        (self.real_features if real else self.fake_features).append(features.to(self.device, torch.float64))

    def update_features(self, features: torch.Tensor, real: bool) -> None:
        """Add precomputed ``(B, 72)`` / ``(B, 32)`` feature vectors (e.g. cached reference features)."""
        self.update(features=features, real=real)

    def reset(self) -> None:
        if self.reset_real_features:
            super().reset()
            return
        kept = list(self.real_features) if isinstance(self.real_features, list) else [self.real_features]
        super().reset()
        self.real_features = kept

    def constant_real_features(self, tolerance: float = 1e-8) -> int:
        """How many feature dimensions do not vary over the real set (population std <= ``tolerance``).

        The reference normalisation divides by ``std + 1e-10``, so a generated set that differs from the real
        one in any such dimension gets a distance of order 1e10-1e20: a property of a small or uniform real
        set (e.g. a synthetic one), which a report should state beside the figure."""
        real = self.real_features
        if isinstance(real, list) and not real:
            return 0
        return int((dim_zero_cat(real).to(torch.float64).std(0, correction=0) <= tolerance).sum())

    def _normalised_sets(self) -> tuple[torch.Tensor, torch.Tensor]:
        if (isinstance(self.real_features, list) and not self.real_features) or (
            isinstance(self.fake_features, list) and not self.fake_features
        ):
            raise RuntimeError(f"{type(self).__name__}: add real and generated sequences before compute()")
        real = dim_zero_cat(self.real_features).to(torch.float64)
        fake = dim_zero_cat(self.fake_features).to(torch.float64)
        if real.shape[0] < 2 or fake.shape[0] < 2:
            raise RuntimeError(
                f"{type(self).__name__}: needs at least 2 real and 2 generated sequences, "
                f"got {real.shape[0]} and {fake.shape[0]}"
            )
        return normalise_by_reference(real, fake)


class FrechetMotionDistance(_ReferenceNormalisedMetric):
    """FID_k (``feature="kinetic"``) or FID_g (``feature="geometric"``) of generated vs real dance.

    Args:
        feature: ``"kinetic"`` (72-d) or ``"geometric"`` (32-d).
        fps: frame rate of the positions (kinetic feature time step).
        zero_start: subtract the frame-0 root from all joints first (Bailando protocol).
        published_acceleration_bug: kinetic EE as in the released code (default, comparable to papers).
        reset_real_features: ``False`` keeps the real set across ``reset()``.

    Examples:
        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> real, generated = torch.randn(8, 10, 24, 3), 2 * torch.randn(8, 10, 24, 3)
        >>> fid_k = FrechetMotionDistance("kinetic")
        >>> fid_k.update(real, real=True)
        >>> fid_k.update(real, real=False)
        >>> abs(float(fid_k.compute())) < 1e-4  # the real set against itself
        True
        >>> fid_k.reset()
        >>> fid_k.update(real, real=True)
        >>> fid_k.update(generated, real=False)
        >>> bool(fid_k.compute() > 1)
        True
    """

    higher_is_better = False

    def compute(self) -> torch.Tensor:
        real, fake = self._normalised_sets()
        return frechet_distance(fake.mean(0), torch.cov(fake.T), real.mean(0), torch.cov(real.T))


class MotionDiversity(_ReferenceNormalisedMetric):
    """Div_k / Div_g: mean pairwise distance of generated features normalised by the real statistics.

    Same arguments as :class:`FrechetMotionDistance`; the real set only supplies the normalisation.
    For the ground-truth row of the tables, feed the real set as both real and generated.

    Examples:
        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> real = torch.randn(8, 10, 24, 3)
        >>> div_k = MotionDiversity("kinetic")
        >>> div_k.update(real, real=True)
        >>> div_k.update(real, real=False)
        >>> round(float(div_k.compute()), 2)
        12.79
    """

    higher_is_better = True

    def compute(self) -> torch.Tensor:
        _, fake = self._normalised_sets()
        return average_pairwise_distance(fake)
