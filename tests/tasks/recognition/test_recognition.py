"""Action recognition: model pooling, LightningModule, data module, confusion matrix, end-to-end runs."""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from lightning.pytorch import Trainer

from skeleton_mamba.errors import DataFileError, DatasetNotFoundError
from skeleton_mamba.tasks.recognition.confusion import save_confusion_matrix
from skeleton_mamba.tasks.recognition.data import RecognitionDataModule
from skeleton_mamba.tasks.recognition.model import ActionRecognizer, body_presence
from skeleton_mamba.tasks.recognition.module import ActionRecognitionModule
from skeleton_mamba.tasks.recognition.pyskl import load_annotations, save_annotations
from skeleton_mamba.tasks.recognition.scores import load_scores
from skeleton_mamba.tasks.recognition.synthetic import make_synthetic_annotations
from skeleton_mamba.tasks.training.backbone_config import backbone_config
from tests.tasks.recognition.cases import TINY

TINY_YAML = {k: v for k, v in dataclasses.asdict(TINY).items() if k not in ("skeleton", "in_channels")}


def sm_executable() -> str:
    path = Path(sys.executable).with_name("sm")
    if not path.exists():
        pytest.skip(f"console script not installed at {path}")
    return str(path)


def run_sm(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "ignore"}
    return subprocess.run(
        [sm_executable(), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=600
    )


def read_metrics(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def ann_file(tmp_path_factory) -> Path:
    """A PYSKL pickle of 3 separable classes: 16 training and 8 validation samples per class."""
    path = tmp_path_factory.mktemp("pyskl") / "synthetic_3danno.pkl"
    return save_annotations(make_synthetic_annotations(num_classes=3, num_frames=32, seed=0), path)


# --- model ---------------------------------------------------------------------------------------


def test_pooling_ignores_zero_padded_bodies_and_averages_present_ones():
    torch.manual_seed(0)
    model = ActionRecognizer(TINY, num_classes=4).eval()
    body_a, body_b = torch.randn(2, 1, 1, 12, 25, 3).unbind(0)
    with torch.no_grad():
        # Independent computation: backbone per body, mean over (T, J), mean over the bodies present.
        pooled_a = model.backbone(body_a[:, 0]).mean(dim=(1, 2))
        pooled_b = model.backbone(body_b[:, 0]).mean(dim=(1, 2))
        padded = torch.cat([body_a, torch.zeros_like(body_a)], dim=1)
        both = torch.cat([body_a, body_b], dim=1)
        torch.testing.assert_close(model.embed(padded), pooled_a, rtol=1e-5, atol=1e-6)
        torch.testing.assert_close(model.embed(both), (pooled_a + pooled_b) / 2, rtol=1e-5, atol=1e-6)
        torch.testing.assert_close(model(padded), model.head(pooled_a), rtol=1e-5, atol=1e-6)
    assert body_presence(padded).tolist() == [[True, False]]


def test_module_forward_averages_softmax_over_clips():
    torch.manual_seed(0)
    module = ActionRecognitionModule(backbone=TINY, num_classes=5, skeleton="ntu25", in_channels=3).eval()
    x = torch.randn(2, 3, 1, 8, 25, 3)  # (B, N clips, M, T, J, C)
    with torch.no_grad():
        expected = torch.stack([module.model(x[:, n]).softmax(-1) for n in range(3)]).mean(0)
        torch.testing.assert_close(module(x), expected, rtol=1e-5, atol=1e-6)


def test_linked_skeleton_and_in_channels_replace_the_backbone_fields():
    module = ActionRecognitionModule(
        backbone=TINY_YAML, num_classes=400, skeleton="openpose18", in_channels=3
    )
    backbone = module.model.backbone
    assert backbone.skeleton.name == "openpose18" and backbone.skeleton.num_joints == 18
    assert backbone.input_proj.in_features == 3
    assert module.model.head.out_features == 400
    assert set(module.test_metrics) == {"test/top1", "test/top5"}


def test_learning_rate_scales_linearly_with_the_global_batch():
    module = ActionRecognitionModule(backbone=TINY, num_classes=3, batch_size=16, lr=0.1, base_batch_size=128)
    assert module.effective_lr() == pytest.approx(0.1 * 16 / 128)  # no trainer: one device
    module.trainer = Trainer(accelerator="cpu", devices=1, accumulate_grad_batches=4, logger=False)
    assert module.effective_lr() == pytest.approx(0.1 * 16 * 4 / 128)


def test_hyperparameters_are_plain_and_rebuild_the_module(tmp_path):
    module = ActionRecognitionModule(backbone=TINY, num_classes=3)
    path = tmp_path / "hparams.pt"
    torch.save({"hyper_parameters": dict(module.hparams)}, path)
    hparams = torch.load(path, weights_only=True)["hyper_parameters"]  # as LightningCLI reads --ckpt_path
    assert backbone_config(hparams["backbone"]) == dataclasses.replace(TINY)
    rebuilt = ActionRecognitionModule(**hparams)
    assert [p.shape for p in rebuilt.parameters()] == [p.shape for p in module.parameters()]


# --- confusion matrix -----------------------------------------------------------------------------


def test_confusion_matrix_files_hold_the_counts(tmp_path):
    rng = np.random.default_rng(0)
    target, pred = rng.integers(0, 4, 50), rng.integers(0, 4, 50)
    counts = np.zeros((4, 4), dtype=np.int64)
    np.add.at(counts, (target, pred), 1)  # rows: true class, columns: predicted
    path = save_confusion_matrix(torch.from_numpy(counts), tmp_path / "cm.png", ["a", "b", "c", "d"])
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    np.testing.assert_array_equal(np.loadtxt(tmp_path / "cm.csv", delimiter=",", dtype=np.int64), counts)
    with pytest.raises(ValueError, match="square"):
        save_confusion_matrix(np.zeros((2, 3)), tmp_path / "bad.png")


# --- data -----------------------------------------------------------------------------------------


def test_synthetic_classes_move_their_own_joint_group():
    data = make_synthetic_annotations(num_classes=3, train_per_class=2, val_per_class=1, seed=3)
    again = make_synthetic_annotations(num_classes=3, train_per_class=2, val_per_class=1, seed=3)
    for a, b in zip(data["annotations"], again["annotations"]):
        np.testing.assert_array_equal(a["keypoint"], b["keypoint"])
    assert [len(v) for v in data["split"].values()] == [6, 3]
    right_arm = {8, 9, 10, 11, 23, 24}  # NTU-25 (0-based) right shoulder .. right thumb
    for anno in data["annotations"]:
        swing = anno["keypoint"][0].std(axis=0).max(axis=-1)  # (V,) temporal spread per joint
        moving = set(np.flatnonzero(swing > 0.3).tolist())
        if anno["label"] == 0:
            assert moving == right_arm


def test_data_module_batches_from_a_pyskl_file(ann_file):
    dm = RecognitionDataModule(
        str(ann_file), num_classes=3, clip_len=10, num_clips_test=4, num_person=2, batch_size=5, num_workers=0
    )
    assert (dm.num_classes, dm.skeleton, dm.in_channels, dm.batch_size) == (3, "ntu25", 3, 5)
    dm.setup("fit")
    keypoint, label = next(iter(dm.train_dataloader()))
    assert keypoint.shape == (5, 1, 2, 10, 25, 3) and keypoint.dtype == torch.float32
    assert not keypoint[:, :, 1].any()  # one generated body, the second slot is zero padding
    assert len(dm.datasets["train"]) == 48 and len(dm.datasets["val"]) == 24
    dm.setup("test")
    keypoint, label = next(iter(dm.test_dataloader()))
    assert keypoint.shape == (5, 4, 2, 10, 25, 3)  # 4 test clips
    assert [a["frame_dir"] for a in dm.datasets["test"].annotations][:2] == [
        "xsub_val_000_0000",
        "xsub_val_000_0001",
    ]


def test_two_dimensional_skeletons_give_x_y_score_channels(tmp_path):
    data = make_synthetic_annotations(
        num_classes=2, train_per_class=2, val_per_class=1, skeleton="openpose18"
    )
    path = save_annotations(data, tmp_path / "k.pkl")
    dm = RecognitionDataModule(str(path), num_classes=2, skeleton="openpose18", clip_len=8, num_workers=0)
    assert dm.in_channels == 3
    dm.setup("validate")
    keypoint, _ = dm.datasets["val"][0]
    assert keypoint.shape == (1, 2, 8, 18, 3)
    assert torch.all(keypoint[:, 0, :, :, 2] == 1.0)  # the score channel


def test_data_module_errors_name_the_file_and_the_fix(tmp_path, ann_file):
    with pytest.raises(DatasetNotFoundError, match="sm prepare ntu60"):
        RecognitionDataModule(
            str(tmp_path / "none.pkl"), num_classes=60, prepare_command="sm prepare ntu60 ..."
        )
    with pytest.raises(DataFileError, match="xset_train"):
        RecognitionDataModule(str(ann_file), num_classes=3, train_split="xset_train").setup("fit")
    with pytest.raises(DataFileError, match="labels outside"):
        RecognitionDataModule(str(ann_file), num_classes=2).setup("fit")
    with pytest.raises(DataFileError, match=r"\[25\] joints; skeleton 'openpose18' has 18"):
        RecognitionDataModule(str(ann_file), num_classes=3, skeleton="openpose18").setup("fit")


# --- end to end through the `sm` console script ---------------------------------------------------


@pytest.mark.parametrize("precision", ["32-true", "bf16-mixed"])
def test_sm_fit_learns_separable_classes_then_sm_test_from_its_checkpoint(tmp_path, ann_file, precision):
    recipe = {
        "seed_everything": 0,
        "trainer": {
            "max_epochs": 3,
            "precision": precision,  # --trainer.precision: fit, test and predict
            "accelerator": "cpu",
            "enable_progress_bar": False,
            "log_every_n_steps": 1,
            "logger": [
                {
                    "class_path": "lightning.pytorch.loggers.TensorBoardLogger",
                    "init_args": {"save_dir": "runs"},
                },
                {"class_path": "lightning.pytorch.loggers.CSVLogger", "init_args": {"save_dir": "runs"}},
            ],
            "callbacks": [  # as in the packaged recipes: the best epoch and the last one
                {
                    "class_path": "lightning.pytorch.callbacks.ModelCheckpoint",
                    "init_args": {"monitor": "val/top1", "mode": "max", "filename": "best-{epoch:03d}"},
                },
                {
                    "class_path": "lightning.pytorch.callbacks.ModelCheckpoint",
                    "init_args": {"filename": "last", "save_top_k": 1, "enable_version_counter": False},
                },
            ],
        },
        "model": {
            "class_path": "ActionRecognitionModule",
            "init_args": {"backbone": TINY_YAML, "lr": 0.02, "base_batch_size": 8},
        },
        "data": {
            "class_path": "RecognitionDataModule",
            "init_args": {
                "ann_file": str(ann_file),
                "num_classes": 3,
                "clip_len": 16,
                "num_clips_test": 2,
                "num_person": 1,
                "batch_size": 8,
                "num_workers": 0,
            },
        },
    }
    (tmp_path / "recipe.yaml").write_text("# test recipe\n" + yaml.safe_dump(recipe))
    fit = run_sm(["fit", "--recipe", "recipe.yaml"], tmp_path)
    assert fit.returncode == 0, fit.stderr[-3000:]
    run_dir = tmp_path / "runs" / "lightning_logs" / "version_0"
    assert (run_dir / "config.yaml").is_file() and list(run_dir.glob("events.out.tfevents.*"))
    val = [
        (float(r["val/top1"]), float(r["val/loss"]))
        for r in read_metrics(run_dir / "metrics.csv")
        if r.get("val/top1")
    ]
    assert len(val) == 3
    assert val[-1][0] > 0.6, val  # chance is 1/3
    assert val[-1][1] < val[0][1] < np.log(3), val  # the loss falls, from below chance level
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert saved["model"]["init_args"]["backbone"]["dim"] == 16

    checkpoint = run_dir / "checkpoints" / "last.ckpt"
    assert torch.load(checkpoint, weights_only=True, map_location="cpu")["epoch"] == 2  # the last epoch
    assert len(list((run_dir / "checkpoints").glob("best-*.ckpt"))) == 1
    test = run_sm(["test", "--recipe", "recipe.yaml", "--ckpt_path", str(checkpoint)], tmp_path)
    assert test.returncode == 0, test.stderr[-3000:]
    test_dir = tmp_path / "runs" / "lightning_logs" / "version_1"
    counts = np.loadtxt(test_dir / "confusion_matrix.csv", delimiter=",", dtype=np.int64)
    assert counts.shape == (3, 3) and counts.sum() == 24 and counts.sum(axis=1).tolist() == [8, 8, 8]
    assert (test_dir / "confusion_matrix.png").is_file()
    (row,) = [r for r in read_metrics(test_dir / "metrics.csv") if r.get("test/top1")]
    assert float(row["test/top1"]) == pytest.approx(np.trace(counts) / counts.sum(), abs=1e-6)
    assert float(row["test/top1"]) > 0.6
    scores = load_scores(test_dir)  # every sample's class scores, named, in the split's order
    assert list(scores.samples) == load_annotations(ann_file)["split"]["xsub_val"]
    assert (scores.split, scores.feats, scores.checkpoint) == ("xsub_val", "j", str(checkpoint))
    np.testing.assert_allclose(scores.prob.sum(axis=1), 1.0, atol=1e-5)
    predicted = np.zeros((3, 3), dtype=np.int64)
    np.add.at(predicted, (scores.labels, scores.prob.argmax(axis=1)), 1)
    np.testing.assert_array_equal(predicted, counts)
    fused = run_sm(["ensemble", str(test_dir), str(test_dir), "--weights", "1", "3", "--out", "e"], tmp_path)
    assert fused.returncode == 0, fused.stderr[-3000:]
    report = json.loads((tmp_path / "e" / "ensemble.json").read_text())
    assert report["ensemble"]["top1"] == pytest.approx(float(row["test/top1"]), abs=1e-6)

    predict = run_sm(["predict", "--recipe", "recipe.yaml", "--ckpt_path", str(checkpoint)], tmp_path)
    assert predict.returncode == 0, predict.stderr[-3000:]
    with (tmp_path / "runs" / "lightning_logs" / "version_2" / "predictions.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 24 and len({r["sample"] for r in rows}) == 24
    predicted = np.zeros((3, 3), dtype=np.int64)
    for r in rows:
        predicted[int(r["label"]), int(r["predicted"])] += 1
        probs = [float(pair.split(":")[1]) for pair in r["top5"].split(";")]
        assert len(probs) == 3 and probs == sorted(probs, reverse=True)
        assert sum(probs) == pytest.approx(1.0, abs=1e-3)
        assert probs[0] == pytest.approx(float(r["probability"]), abs=1e-4)
    np.testing.assert_array_equal(predicted, counts)  # the same clips and weights as `sm test`
