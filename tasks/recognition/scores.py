"""Per-sample class scores of ``sm test`` (``scores.npz`` in the run's log dir), read by ``sm ensemble``.

[PYSKL]'s multi-stream protocol trains one model per stream (joint, bone, joint motion, bone motion), dumps
each model's test scores (``tools/test.py --out result.pkl``: the clip-averaged softmax, its default
``average_clips='prob'``) and adds them with weights. ``sm test`` of a recognition recipe writes the same
scores, one row per sample of the test split in the split's order, to ``scores.npz``:

- ``sample`` (N,) str: the annotation's ``frame_dir``; ``label`` (N,) int64: the annotated class;
- ``prob`` (N, K) float32: the softmax probabilities averaged over the sample's clips (PYSKL's scores);
- ``logit`` (N, K) float32: the logits averaged over the clips (PYSKL's ``average_clips='score'``);
- ``split``, ``source`` (the annotation file), ``feats`` (the stream, e.g. ``j,b``), ``checkpoint``:
  str; ``class_names`` (K,) str when the model has them.

The file holds plain arrays only (read with ``allow_pickle=False``). Numpy only: no torch.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.atomic import atomic_open

__all__ = ["SCORE_KINDS", "SCORES_FILE", "RunScores", "load_scores", "save_scores"]

SCORES_FILE = "scores.npz"
SCORE_KINDS = ("prob", "logit")
_TEXT = ("split", "source", "feats", "checkpoint")


@dataclasses.dataclass(frozen=True)
class RunScores:
    """The test scores of one run (see the module docstring); ``path`` is the file they were read from."""

    path: Path
    samples: tuple[str, ...]
    labels: np.ndarray
    prob: np.ndarray
    logit: np.ndarray
    split: str = ""
    source: str = ""
    feats: str = ""
    checkpoint: str = ""
    class_names: tuple[str, ...] | None = None

    @property
    def num_classes(self) -> int:
        return int(self.prob.shape[1])

    def scores(self, kind: str) -> np.ndarray:
        """The (N, K) scores of ``kind``: ``prob`` or ``logit``."""
        if kind not in SCORE_KINDS:
            raise ValueError(f"score kind must be one of {SCORE_KINDS}, got {kind!r}")
        return self.prob if kind == "prob" else self.logit


def save_scores(
    path: str | os.PathLike[str],
    samples: Sequence[str],
    labels: np.ndarray,
    prob: np.ndarray,
    logit: np.ndarray,
    *,
    split: str = "",
    source: str = "",
    feats: Sequence[str] = (),
    checkpoint: str = "",
    class_names: Sequence[str] | None = None,
) -> Path:
    """Write ``scores.npz`` (module docstring) atomically; returns its path.

    Raises:
        ValueError: the arrays do not hold one row per sample, or the names are not K.
    """
    labels = np.asarray(labels, dtype=np.int64)
    prob, logit = np.asarray(prob, dtype=np.float32), np.asarray(logit, dtype=np.float32)
    n = len(samples)
    if labels.shape != (n,) or prob.ndim != 2 or prob.shape[0] != n or logit.shape != prob.shape:
        shapes = f"labels {labels.shape}, prob {prob.shape}, logit {logit.shape}"
        raise ValueError(f"scores of {n} samples: {shapes}")
    arrays = {
        "sample": np.asarray(list(samples), dtype=str),
        "label": labels,
        "prob": prob,
        "logit": logit,
        "split": np.asarray(split),
        "source": np.asarray(source),
        "feats": np.asarray(",".join(feats)),
        "checkpoint": np.asarray(checkpoint),
    }
    if class_names is not None:
        if len(class_names) != prob.shape[1]:
            raise ValueError(f"{len(class_names)} class names for {prob.shape[1]} classes")
        arrays["class_names"] = np.asarray(list(class_names), dtype=str)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path, "wb") as handle:
        np.savez(handle, **arrays)
    return path


def load_scores(run: str | os.PathLike[str]) -> RunScores:
    """The scores of ``run``: a run folder holding ``scores.npz`` or the file itself.

    Raises:
        InputError: no such file, not a score file, or arrays of the wrong shape, type or value (non-finite
            scores, negative labels); the message names the run.
    """
    run = Path(run)
    path = run / SCORES_FILE if run.is_dir() else run
    if not path.is_file():
        where = f"{run}: no {SCORES_FILE} in it" if run.is_dir() else f"{run}: no such run folder or file"
        raise InputError(f"{where} (sm test of a recognition recipe writes {SCORES_FILE} into its log dir)")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError) as err:
        raise InputError(f"{path}: not a score file of sm test ({err})") from None
    missing = [key for key in ("sample", "label", "prob", "logit") if key not in arrays]
    if missing:
        raise InputError(f"{path}: not a score file of sm test (no {', '.join(missing)})")
    samples, labels, prob, logit = (arrays[k] for k in ("sample", "label", "prob", "logit"))
    n = samples.shape[0] if samples.ndim == 1 else -1
    if samples.dtype.kind != "U" or n < 1:
        raise InputError(f"{path}: 'sample' must be a non-empty list of names")
    if labels.shape != (n,) or labels.dtype.kind not in "iu" or (labels < 0).any():
        raise InputError(f"{path}: 'label' must hold one class index >= 0 per sample ({n})")
    for name, array in (("prob", prob), ("logit", logit)):
        if array.ndim != 2 or array.shape[0] != n or array.shape[1] < 1 or array.dtype.kind != "f":
            raise InputError(f"{path}: '{name}' must be ({n}, K) scores, got {array.dtype} {array.shape}")
        if not np.isfinite(array).all():
            raise InputError(f"{path}: '{name}' holds NaN or Inf")
    if logit.shape != prob.shape or (labels >= prob.shape[1]).any():
        raise InputError(f"{path}: 'logit' {logit.shape} / labels do not fit 'prob' {prob.shape}")
    text = {}
    for key in _TEXT:
        value = arrays.get(key, np.asarray(""))
        if value.ndim != 0 or value.dtype.kind != "U":
            raise InputError(f"{path}: '{key}' must be a string")
        text[key] = str(value)
    names = arrays.get("class_names")
    if names is not None and (names.dtype.kind != "U" or names.shape != (prob.shape[1],)):
        raise InputError(f"{path}: 'class_names' must hold {prob.shape[1]} names")
    return RunScores(
        path=path,
        samples=tuple(samples.tolist()),
        labels=labels.astype(np.int64),
        prob=prob.astype(np.float64),
        logit=logit.astype(np.float64),
        class_names=None if names is None else tuple(names.tolist()),
        **text,
    )
