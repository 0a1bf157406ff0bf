"""Confusion-matrix figure and table for the test split (matplotlib, headless)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display on training machines
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from skeleton_mamba.io.atomic import atomic_open, atomic_path

__all__ = ["save_confusion_matrix"]

# Beyond this many classes the per-cell counts and tick labels are unreadable and are left out.
MAX_ANNOTATED_CLASSES = 20


def save_confusion_matrix(
    matrix: torch.Tensor | np.ndarray, path: str | Path, class_names: Sequence[str] | None = None
) -> Path:
    """Save a (K, K) confusion matrix (rows: true class, columns: predicted) as an image and a CSV.

    The image shows each row normalized to recall (the diagonal is the per-class accuracy); the CSV
    beside it (same stem, ``.csv``) holds the raw counts, one row per true class.

    Args:
        matrix: (K, K) counts.
        path: the image path (``.png``, ``.pdf``, ``.svg``).
        class_names: K names for the axes (optional; shown when K <= 20).

    Returns:
        The image path.
    """
    counts = np.asarray(matrix.detach().cpu() if isinstance(matrix, torch.Tensor) else matrix, dtype=np.int64)
    if counts.ndim != 2 or counts.shape[0] != counts.shape[1]:
        raise ValueError(f"confusion matrix must be square (K, K), got shape {counts.shape}")
    k = counts.shape[0]
    if class_names is not None and len(class_names) != k:
        raise ValueError(f"{len(class_names)} class names for a {k}-class confusion matrix")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path.with_suffix(".csv"), "w") as f:
        np.savetxt(f, counts, fmt="%d", delimiter=",")

    totals = counts.sum(axis=1, keepdims=True)
    recall = np.divide(counts, totals, out=np.zeros(counts.shape, dtype=np.float64), where=totals > 0)
    size = min(5.5 + 0.12 * k, 24)
    fig, ax = plt.subplots(figsize=(size, size))
    image = ax.imshow(recall, vmin=0.0, vmax=1.0, cmap="Blues")
    fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04, label="fraction of the true class")
    ax.set_xlabel("predicted class")
    ax.set_ylabel("true class")
    ax.set_title(
        f"Confusion matrix ({int(counts.sum())} samples, "
        f"accuracy {np.trace(counts) / max(counts.sum(), 1):.3f})",
        fontsize=10,
    )
    if k <= MAX_ANNOTATED_CLASSES:
        names = list(class_names) if class_names is not None else [str(i) for i in range(k)]
        ax.set_xticks(range(k), names, rotation=90)
        ax.set_yticks(range(k), names)
        for i in range(k):
            for j in range(k):
                color = "white" if recall[i, j] > 0.5 else "black"
                ax.text(j, i, str(counts[i, j]), ha="center", va="center", color=color, fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return path
