"""Recognition on two ranks (DDP over gloo on the CPU), as ``sm`` users launch it ([PYSKL]'s dist_train /
dist_test): every training sample read exactly once per epoch across the ranks, and ``sm test`` on two
processes reports the accuracy of one process and writes one score file in the split's order."""

import csv
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from skeleton_mamba.tasks.recognition.scores import load_scores
from tests.helpers.sm import sm_executable

TESTS = Path(__file__).resolve().parents[2] / "helpers"  # ddp_probe


def _sm(args: list[str], cwd: Path, **env: str) -> str:
    environment = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "ignore", **env}
    environment["PYTHONPATH"] = os.pathsep.join(filter(None, [str(TESTS), environment.get("PYTHONPATH")]))
    proc = subprocess.run([sm_executable(), *args], cwd=cwd, env=environment, capture_output=True, text=True,
                          timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout + proc.stderr


def _logged_top1(run: Path) -> float:
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    return next(float(row["test/top1"]) for row in rows if row.get("test/top1"))


def test_two_ranks_train_on_every_sample_once_and_test_like_one(tmp_path):
    """48 training samples, batch 8, two ranks, two epochs; then 21 test samples (uneven over 2 ranks:
    torch's DistributedSampler would score one of them twice)."""
    probe = tmp_path / "probe"
    probe.mkdir()
    ddp = ["--trainer.devices", "2", "--trainer.strategy", "ddp"]
    fit = ["fit", "--recipe", "recognition_synthetic.yaml", *ddp, "--trainer.max_epochs", "2",
           "--trainer.callbacks+=ddp_probe.SampleProbe"]  # fmt: skip
    _sm(fit, tmp_path, SM_ALLOW_IMPORT="ddp_probe", SM_PROBE_DIR=str(probe))
    for epoch in (0, 1):
        ranks = [json.loads((probe / f"rank{r}-epoch{epoch}.json").read_text()) for r in (0, 1)]
        assert all(rank["world"] == 2 for rank in ranks)
        assert [len(rank["seen"]) for rank in ranks] == [24, 24]  # 3 batches of 8 on each rank
        assert sorted(ranks[0]["seen"] + ranks[1]["seen"]) == list(range(48)), epoch
    orders = [json.loads((probe / f"rank0-epoch{e}.json").read_text())["seen"] for e in (0, 1)]
    assert orders[0] != orders[1]  # the sampler's epoch is set: a new shuffle each epoch

    runs = tmp_path / "runs" / "recognition_synthetic"
    checkpoint = runs / "version_0" / "checkpoints" / "last.ckpt"
    test = ["test", "--recipe", "recognition_synthetic.yaml", "--ckpt_path", str(checkpoint),
            "--data.init_args.val_per_class", "7"]  # fmt: skip
    one = _sm([*test, "--trainer.devices", "1"], tmp_path)
    two = _sm([*test, *ddp], tmp_path)
    assert "21 samples' class scores saved" in one and "21 samples' class scores saved" in two
    single, double = (load_scores(runs / f"version_{v}") for v in (1, 2))
    assert single.samples == double.samples and len(single.samples) == 21
    np.testing.assert_array_equal(single.labels, double.labels)
    np.testing.assert_allclose(double.prob, single.prob, rtol=1e-5, atol=1e-6)
    top1 = float(np.mean(single.prob.argmax(axis=1) == single.labels))
    assert _logged_top1(runs / "version_1") == pytest.approx(top1, abs=1e-6)
    assert _logged_top1(runs / "version_2") == pytest.approx(top1, abs=1e-6)
