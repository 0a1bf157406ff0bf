"""``sm ensemble RUN... [--weights W...] [--score prob|logit] [--out DIR]``: multi-stream recognition.

[PYSKL] trains one model per input stream (``GenSkeFeat``'s joint, bone, joint-motion and bone-motion
features; here ``--data.init_args.feats``), tests each, and adds the test scores with weights; its
READMEs fuse two streams 1:1 (J + B) and four 2:2:1:1 (J, B, JM, BM), and [ProtoGCN]'s ``tools/ensemble.py``
does the same on PYSKL's dumps. The scores are those ``sm test`` saves (:mod:`.scores`): by default the
clip-averaged softmax probabilities that PYSKL's ``tools/test.py --out`` dumps (``average_clips='prob'``),
with ``--score logit`` the clip-averaged logits.

The runs must score the same samples of the same split in the same order, with the same labels and class
count; otherwise the command refuses, naming the first run that differs from the first run. It prints each
run's top-1 / top-5 / mean class accuracy and the ensemble's and, with ``--out DIR``, writes
``ensemble.json`` (the runs, weights and metrics), ``ensemble_scores.npz`` (sample, label, the fused
``score``) and ``confusion_matrix.png`` / ``.csv`` (:func:`.confusion.save_confusion_matrix`).

Top-k counts a sample as correct when its label is among the k highest scores, ties going to the lower
class index (a stable sort); top-5 is reported when there are more than 5 classes, as ``sm test`` does.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_folder, writing_outputs
from skeleton_mamba.tasks.recognition.ensemble_args import build_parser
from skeleton_mamba.tasks.recognition.scores import RunScores, load_scores

__all__ = [
    "check_same_samples",
    "confusion_counts",
    "evaluate",
    "fuse",
    "main",
    "mean_class_accuracy",
    "top_k_accuracy",
]

COMMAND = "sm ensemble"
OUTPUTS = ("ensemble.json", "ensemble_scores.npz", "confusion_matrix.png", "confusion_matrix.csv")


def _first_difference(a: Sequence[str], b: Sequence[str]) -> str:
    """How sample list ``b`` differs from ``a`` (missing, extra, or the first place the order differs)."""
    missing, extra = [s for s in a if s not in set(b)], [s for s in b if s not in set(a)]
    if missing or extra:
        parts = []
        if missing:
            parts.append(f"{len(missing)} of its samples missing (e.g. {missing[0]!r})")
        if extra:
            parts.append(f"{len(extra)} samples it lacks (e.g. {extra[0]!r})")
        return ", ".join(parts)
    if len(a) != len(b):
        return f"{len(b)} rows against {len(a)} (a sample repeated)"
    i = next(i for i, (x, y) in enumerate(zip(a, b)) if x != y)
    return f"the same samples in another order (row {i}: {b[i]!r}, not {a[i]!r})"


def check_same_samples(runs: Sequence[RunScores]) -> None:
    """Refuse runs that do not score the same samples of the same split, in the same order, with the same
    labels and classes as the first run.

    Raises:
        InputError: naming the first run that differs and how.
    """
    first = runs[0]
    for run in runs[1:]:
        where = f"{run.path} differs from {first.path}"
        if run.split != first.split:
            raise InputError(f"{where}: its test split is {run.split!r}, not {first.split!r}")
        if run.samples != first.samples:
            raise InputError(f"{where}: {_first_difference(first.samples, run.samples)}")
        if not np.array_equal(run.labels, first.labels):
            i = int(np.flatnonzero(run.labels != first.labels)[0])
            sample, label, expected = run.samples[i], run.labels[i], first.labels[i]
            raise InputError(f"{where}: sample {sample!r} has label {label}, not {expected}")
        if run.num_classes != first.num_classes:
            raise InputError(f"{where}: {run.num_classes} classes, not {first.num_classes}")


def fuse(scores: Sequence[np.ndarray], weights: Sequence[float] | None = None) -> np.ndarray:
    """The weighted sum ``sum_i w_i * scores_i`` (float64; ``weights`` default 1 each), as [PYSKL] fuses."""
    weights = [1.0] * len(scores) if weights is None else list(weights)
    if len(weights) != len(scores) or not scores:
        raise ValueError(f"{len(weights)} weights for {len(scores)} score arrays")
    return sum(float(w) * np.asarray(s, dtype=np.float64) for w, s in zip(weights, scores))


def _ranking(scores: np.ndarray) -> np.ndarray:
    """Class indices by decreasing score, ties by increasing index (stable)."""
    return np.argsort(-np.asarray(scores, dtype=np.float64), axis=1, kind="stable")


def top_k_accuracy(scores: np.ndarray, labels: np.ndarray, k: int) -> float:
    """Fraction of samples whose label is among their ``k`` highest scores."""
    top = _ranking(scores)[:, :k]
    return float((top == np.asarray(labels)[:, None]).any(axis=1).mean())


def confusion_counts(scores: np.ndarray, labels: np.ndarray, num_classes: int) -> np.ndarray:
    """(K, K) counts, rows the true class, columns the top-1 prediction."""
    counts = np.zeros((num_classes, num_classes), dtype=np.int64)
    np.add.at(counts, (np.asarray(labels), _ranking(scores)[:, 0]), 1)
    return counts


def mean_class_accuracy(counts: np.ndarray) -> float:
    """The mean over the classes present of their top-1 accuracy (PYSKL's ``mean_class_accuracy``)."""
    totals = counts.sum(axis=1)
    present = totals > 0
    return float((np.diag(counts)[present] / totals[present]).mean())


def evaluate(scores: np.ndarray, labels: np.ndarray) -> dict:
    """top-1, top-5 (None for K <= 5) and mean class accuracy of (N, K) ``scores``."""
    k = scores.shape[1]
    counts = confusion_counts(scores, labels, k)
    return {
        "top1": top_k_accuracy(scores, labels, 1),
        "top5": top_k_accuracy(scores, labels, 5) if k > 5 else None,
        "mean_class_accuracy": mean_class_accuracy(counts),
    }


def _percent(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.2f}"


def main(argv: list[str] | None = None) -> int:
    """``sm ensemble`` (see the module docstring); returns the exit code."""
    args = build_parser().parse_args(argv)
    if args.out is not None:
        claim_output_folder(args.out, COMMAND, OUTPUTS, overwrite=args.overwrite)
    runs = [load_scores(run) for run in args.runs]
    check_same_samples(runs)
    weights = [1.0] * len(runs) if args.weights is None else list(args.weights)
    fused = fuse([run.scores(args.score) for run in runs], weights)
    labels = runs[0].labels
    result = evaluate(fused, labels)
    rows = [(run, weight, evaluate(run.scores(args.score), labels)) for run, weight in zip(runs, weights)]

    first = runs[0]
    print(f"sm ensemble: {len(runs)} runs, {len(labels)} samples of split {first.split or '?'!r}, "
          f"{first.num_classes} classes; weighted sum of the {args.score} scores")  # fmt: skip
    print(f"  {'weight':>6}  {'top-1':>6}  {'top-5':>6}  {'mean-class':>10}  run (feats)")
    for run, weight, metrics in rows:
        print(f"  {weight:>6g}  {_percent(metrics['top1']):>6}  {_percent(metrics['top5']):>6}  "
              f"{_percent(metrics['mean_class_accuracy']):>10}  {run.path} ({run.feats or '?'})")  # fmt: skip
    print(f"  {'fused':>6}  {_percent(result['top1']):>6}  {_percent(result['top5']):>6}  "
          f"{_percent(result['mean_class_accuracy']):>10}  ensemble")  # fmt: skip
    if args.out is None:
        return 0

    report = {
        "split": first.split,
        "source": first.source,
        "samples": len(labels),
        "classes": first.num_classes,
        "score": args.score,
        "runs": [
            {
                "scores": str(run.path),
                "weight": weight,
                "feats": run.feats,
                "checkpoint": run.checkpoint,
                "source": run.source,
                **metrics,
            }
            for run, weight, metrics in rows
        ],  # fmt: skip
        "ensemble": result,
    }
    from skeleton_mamba.tasks.recognition.confusion import save_confusion_matrix  # lazy: matplotlib

    with writing_outputs(args.out, COMMAND, OUTPUTS) as out:
        with atomic_open(out / "ensemble.json", "w", encoding="utf-8") as handle:
            handle.write(json.dumps(report, indent=2) + "\n")
        with atomic_open(out / "ensemble_scores.npz", "wb") as handle:
            np.savez(handle, sample=np.asarray(first.samples, dtype=str), label=labels, score=fused,
                     weights=np.asarray(weights, dtype=np.float64))  # fmt: skip
        counts = confusion_counts(fused, labels, first.num_classes)
        picture = save_confusion_matrix(counts, out / "confusion_matrix.png", first.class_names)
    print(f"  {out / 'ensemble.json'}\n  {picture} (and {picture.with_suffix('.csv').name})")
    return 0
