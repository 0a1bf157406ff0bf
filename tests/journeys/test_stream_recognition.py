"""Journey (b): a user's NTU RGB+D ``.skeleton`` file, or keypoints saved as ``.npy``, streamed through a
causal recognizer with ``sm stream --task recognition``: the per-frame table and plot are written and
listed, the probabilities are distributions over the classes, and the raw file gives exactly what its
normalised keypoints (PYSKL ``PreNormalize3D``, as the recipes' pipeline) give as a ``.npy``."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.motion.formats.ntu import read_skeleton_file
from skeleton_mamba.tasks.recognition.module import ActionRecognitionModule
from skeleton_mamba.tasks.recognition.transforms import pre_normalize_3d
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.checkpoint_files import save_module_checkpoint
from tests.helpers.repo import shared_file

CLASSES = ["drink water", "eat meal", "brush teeth"]


@pytest.fixture(scope="module")
def causal_ckpt(tmp_path_factory):
    """A tiny causal recognizer (random weights) saved as a Lightning checkpoint."""
    torch.manual_seed(0)
    backbone = {"dim": 16, "depth": 1, "heads": 2, "mlp_dim": 32, "causal": True,
                "mixer": {"d_state": 8, "headdim": 8, "chunk_size": 16}}  # fmt: skip
    module = ActionRecognitionModule(backbone=backbone, num_classes=3, class_names=CLASSES)
    return save_module_checkpoint(module, tmp_path_factory.mktemp("rec") / "causal.ckpt")


def _stream(ckpt, skeleton, out, capsys) -> tuple[np.ndarray, str]:
    args = ["stream", "--task", "recognition", "--ckpt", str(ckpt), "--skeleton", str(skeleton)]
    assert sm_main([*args, "--out", str(out), "--threads", "1"]) == 0
    printed = capsys.readouterr().out
    with open(out / f"{skeleton.stem}_online.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["frame", "top_class", *CLASSES]
    prob = np.array([[float(v) for v in row[2:]] for row in rows[1:]])
    assert [row[1] for row in rows[1:]] == [CLASSES[k] for k in prob.argmax(axis=1)]
    return prob, printed


def test_ntu_skeleton_file_streams_like_its_normalised_keypoints(causal_ckpt, tmp_path, capsys):
    path = shared_file("ntu/S001C001P001R001A001.skeleton")
    prob, printed = _stream(causal_ckpt, path, tmp_path / "raw", capsys)
    raw = read_skeleton_file(path).keypoints(max_bodies=2)  # (1, 103, 25, 3)
    assert prob.shape == (raw.shape[1], 3)
    np.testing.assert_allclose(prob.sum(axis=1), 1.0, atol=1e-5)
    table, plot = tmp_path / "raw" / f"{path.stem}_online.csv", tmp_path / "raw" / f"{path.stem}_online.png"
    assert str(table) in printed and str(plot) in printed and plot.stat().st_size > 0
    assert f"{raw.shape[1]} frames, 1 body" in printed

    npy = tmp_path / f"{path.stem}.npy"
    np.save(npy, pre_normalize_3d(raw))
    same, _ = _stream(causal_ckpt, npy, tmp_path / "npy", capsys)
    np.testing.assert_allclose(prob, same, atol=1e-6, rtol=0)


def test_generated_two_body_keypoints(causal_ckpt, tmp_path, capsys):
    rng = np.random.default_rng(0)
    keypoints = rng.normal(0, 0.3, (2, 24, 25, 3)).astype(np.float32)  # (M, T, J, C)
    np.save(tmp_path / "pair.npy", keypoints)
    prob, printed = _stream(causal_ckpt, tmp_path / "pair.npy", tmp_path / "out", capsys)
    assert prob.shape == (24, 3) and "24 frames, 2 bodies" in printed
    np.testing.assert_allclose(prob.sum(axis=1), 1.0, atol=1e-5)


def test_other_files_refused_on_one_line(causal_ckpt, tmp_path, capsys):
    (tmp_path / "clip.bvh").write_text("HIERARCHY\n")
    args = ["stream", "--task", "recognition", "--ckpt", str(causal_ckpt), "--out", str(tmp_path / "o")]
    assert sm_main([*args, "--skeleton", str(tmp_path / "clip.bvh")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "clip.bvh: expected an NTU .skeleton file or a .npy of keypoints" in err[0]
