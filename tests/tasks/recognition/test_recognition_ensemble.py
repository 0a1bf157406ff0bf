"""``sm ensemble``: the weighted sum of several runs' ``sm test`` scores ([PYSKL]'s multi-stream fusion)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.recognition import ensemble
from skeleton_mamba.tasks.recognition.scores import SCORES_FILE, load_scores, save_scores

SAMPLES = ["S001C001P001R001A003", "S001C001P001R001A001", "S001C001P001R001A007"]
LABELS = [2, 0, 6]
K = 7
# three runs' scores (plain numbers, so that the sums are easy to check by hand)
A = [[1, 0, 3, 0, 0, 0, 0], [4, 0, 0, 0, 0, 0, 2], [0, 0, 0, 0, 0, 5, 1]]
B = [[0, 1, 0, 1, 1, 1, 1], [0, 2, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0, 4]]
C = [[6, 0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 2, 0, 0], [0, 0, 0, 0, 0, 0, 2]]
WEIGHTS = [2.0, 1.0, 0.5]
# 2 A + B + 0.5 C, by hand
FUSED = [[5, 1, 6, 1, 1, 1, 1], [8, 2, 0, 0, 1, 0, 4], [0, 0, 0, 0, 0, 10, 7]]
# top-1 / top-5 by hand (ties go to the lower class):
#   fused: 2 (label 2) yes, 0 (label 0) yes, 5 (label 6) no -> 2/3; the label is in every top 5 -> 3/3
#   A: 2 yes, 0 yes, 5 no -> 2/3; label 6 ranks second in sample 3 -> 3/3
#   B: sample 1 ranks 1, 3, 4, 5, 6 before class 2 -> top-1 no, top-5 no; sample 2: 1 (top-5 yes); sample 3: 6
#      -> top-1 1/3, top-5 2/3
#   C: 0 no, 4 no, 6 yes -> 1/3; top-5 3/3
EXPECTED = {"A": (2 / 3, 1.0), "B": (1 / 3, 2 / 3), "C": (1 / 3, 1.0), "fused": (2 / 3, 1.0)}


def write_run(folder: Path, prob, samples=SAMPLES, labels=LABELS, split="xsub_val", feats=("j",)) -> Path:
    """A run folder holding scores.npz, as sm test writes it (the logits: the scores halved)."""
    prob = np.asarray(prob, dtype=np.float32)
    save_scores(folder / SCORES_FILE, samples, labels, prob, prob / 2, split=split, source="ntu60.pkl",
                feats=feats, checkpoint=str(folder / "last.ckpt"))  # fmt: skip
    return folder


@pytest.fixture
def runs(tmp_path) -> list[Path]:
    streams = (("A", A, "j"), ("B", B, "b"), ("C", C, "jm"))
    return [write_run(tmp_path / name, scores, feats=(feat,)) for name, scores, feat in streams]


def test_fuse_is_the_weighted_sum_and_top_k_counts_as_by_hand():
    fused = ensemble.fuse([np.array(A), np.array(B), np.array(C)], WEIGHTS)
    np.testing.assert_array_equal(fused, FUSED)
    np.testing.assert_array_equal(ensemble.fuse([np.array(A), np.array(B)]), np.add(A, B))  # weights 1
    for name, scores in (("A", A), ("B", B), ("C", C), ("fused", FUSED)):
        top1, top5 = EXPECTED[name]
        assert ensemble.top_k_accuracy(np.array(scores), np.array(LABELS), 1) == pytest.approx(top1), name
        assert ensemble.top_k_accuracy(np.array(scores), np.array(LABELS), 5) == pytest.approx(top5), name
    counts = ensemble.confusion_counts(np.array(FUSED), np.array(LABELS), K)
    assert counts.sum() == 3 and counts[2, 2] == counts[0, 0] == counts[6, 5] == 1
    assert ensemble.mean_class_accuracy(counts) == pytest.approx(2 / 3)  # classes 2, 0, 6 present


def test_sm_ensemble_prints_and_writes_the_fused_metrics(runs, tmp_path, capsys):
    out = tmp_path / "ensemble"
    args = [str(r) for r in runs] + ["--weights", "2", "1", "0.5", "--out", str(out)]
    assert ensemble.main(args) == 0
    printed = capsys.readouterr().out
    assert "3 runs, 3 samples of split 'xsub_val', 7 classes" in printed
    assert "   fused   66.67  100.00       66.67  ensemble" in printed
    report = json.loads((out / "ensemble.json").read_text())
    assert [report[k] for k in ("split", "samples", "classes", "score")] == ["xsub_val", 3, 7, "prob"]
    assert [(r["weight"], r["feats"]) for r in report["runs"]] == [(2.0, "j"), (1.0, "b"), (0.5, "jm")]
    for run, name in zip(report["runs"], "ABC"):
        assert (run["top1"], run["top5"]) == pytest.approx(EXPECTED[name])
    assert (report["ensemble"]["top1"], report["ensemble"]["top5"]) == pytest.approx(EXPECTED["fused"])
    with np.load(out / "ensemble_scores.npz") as saved:
        np.testing.assert_array_equal(saved["score"], FUSED)
        assert saved["sample"].tolist() == SAMPLES and saved["label"].tolist() == LABELS
    counts = np.loadtxt(out / "confusion_matrix.csv", delimiter=",", dtype=np.int64)
    np.testing.assert_array_equal(counts, ensemble.confusion_counts(np.array(FUSED), np.array(LABELS), K))
    assert (out / "confusion_matrix.png").is_file()
    # the logits instead (halved here: the same ranking), and print only without --out
    assert ensemble.main([str(r) for r in runs] + ["--score", "logit"]) == 0
    assert "weighted sum of the logit scores" in capsys.readouterr().out
    assert ensemble.main([str(runs[0]), str(runs[0])]) == 0  # a run twice: its scores doubled, same ranking


@pytest.mark.parametrize(
    "change, message",
    [
        ({"split": "xview_val"}, "its test split is 'xview_val', not 'xsub_val'"),
        ({"samples": SAMPLES[::-1]}, "the same samples in another order (row 0: 'S001C001P001R001A007'"),
        (
            {"samples": SAMPLES[:2], "labels": LABELS[:2]},
            "1 of its samples missing (e.g. 'S001C001P001R001A007')",
        ),
        ({"labels": [2, 0, 5]}, "sample 'S001C001P001R001A007' has label 5, not 6"),
    ],
    ids=["split", "order", "missing", "label"],
)
def test_runs_that_differ_are_refused_naming_the_run(runs, tmp_path, change, message):
    prob = np.array(B)[: len(change.get("samples", SAMPLES))]
    odd = write_run(tmp_path / "odd", prob, **change)
    args = [str(runs[0]), str(runs[1]), str(odd)]
    with pytest.raises(InputError, match="odd") as refused:
        ensemble.main(args)
    assert str(refused.value).startswith(f"{odd / SCORES_FILE} differs from {runs[0] / SCORES_FILE}: ")
    assert message in str(refused.value)
    assert not (tmp_path / "out").exists()


def test_score_files_are_checked(tmp_path):
    with pytest.raises(InputError, match="no scores.npz in it"):
        load_scores(tmp_path)
    np.savez(tmp_path / "other.npz", sample=np.array(["a"]), label=np.array([0]))
    with pytest.raises(InputError, match=r"not a score file of sm test \(no prob, logit\)"):
        load_scores(tmp_path / "other.npz")
    bad = np.array([[np.nan, 1.0]], dtype=np.float32)
    np.savez(tmp_path / "nan.npz", sample=np.array(["a"]), label=np.array([0]), prob=bad, logit=bad)
    with pytest.raises(InputError, match="'prob' holds NaN or Inf"):
        load_scores(tmp_path / "nan.npz")
    run = load_scores(write_run(tmp_path / "run", A))
    assert (run.samples, run.labels.tolist()) == (tuple(SAMPLES), LABELS)
    assert (run.split, run.source, run.feats) == ("xsub_val", "ntu60.pkl", "j")
    np.testing.assert_array_equal(run.scores("logit"), np.array(A) / 2)


def test_sm_ensemble_refuses_on_one_line(runs, tmp_path):
    odd = write_run(tmp_path / "odd", B, split="xview_val")
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    sm = [sys.executable, "-m", "skeleton_mamba.tasks", "ensemble"]
    done = subprocess.run([*sm, str(runs[0]), str(odd)], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(f"sm ensemble: error: {odd / SCORES_FILE} differs from")
    done = subprocess.run(
        [*sm, *map(str, runs), "--weights", "1", "2"], capture_output=True, text=True, env=env
    )
    assert done.returncode == 2
    assert "--weights: 2 weights for 3 runs (give one per run)" in done.stderr
