"""Online recognition with a causal backbone: per-frame probabilities and the early-recognition curve."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.recognition.early import EarlyRecognitionCurve, online_probabilities
from skeleton_mamba.tasks.recognition.model import ActionRecognizer
from skeleton_mamba.tasks.recognition.online import OnlineRecognizer
from skeleton_mamba.tasks.recognition.synthetic import make_synthetic_annotations


def _recognizer(causal=True, input_norm=False) -> ActionRecognizer:
    torch.manual_seed(0)
    cfg = SkeletonMambaConfig(skeleton="ntu25", in_channels=3, dim=16, depth=2, mlp_dim=32, causal=causal,
                              mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16))  # fmt: skip
    model = ActionRecognizer(cfg, num_classes=4, input_norm=input_norm).double()
    if input_norm:  # statistics of its own, so the normalisation is not the identity
        model.input_norm.running_mean.uniform_(-1, 1)
        model.input_norm.running_var.uniform_(0.5, 2.0)
        model.input_norm.weight.data.uniform_(0.5, 1.5)
    return model.eval()


def _two_bodies() -> torch.Tensor:
    torch.manual_seed(1)
    x = torch.randn(2, 2, 20, 25, 3, dtype=torch.float64)
    x[0, 1, :7] = 0  # the second body of sample 0 enters at frame 7
    x[1, 1] = 0  # sample 1 has one body
    return x


def test_online_probabilities_end_at_the_clip_prediction_and_ignore_the_future():
    model, x = _recognizer(), _two_bodies()
    with torch.no_grad():
        online = online_probabilities(model, x)
        torch.testing.assert_close(online[:, -1], model(x).softmax(-1), rtol=0, atol=1e-12)
        # Frame t from the clip cut after t (an independent computation: the clip-level model).
        for t in (0, 6, 7, 13):
            torch.testing.assert_close(online[:, t], model(x[:, :, : t + 1]).softmax(-1), rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="causal"):
        online_probabilities(_recognizer(causal=False), x)


@pytest.mark.parametrize("input_norm", [False, True])
def test_frame_by_frame_recognizer_equals_the_batch_online_probabilities(input_norm):
    model, x = _recognizer(input_norm=input_norm), _two_bodies()
    stream = OnlineRecognizer(model, batch=2, bodies=2)
    steps = torch.stack([stream.push(x[:, :, t]) for t in range(x.shape[2])], dim=1)
    with torch.no_grad():
        torch.testing.assert_close(steps, online_probabilities(model, x), rtol=0, atol=1e-10)


def test_input_norm_standardises_each_joint_channel_over_frames_and_bodies():
    """``input_norm`` in training: every (joint, channel) of the batch to mean 0, variance 1 (the bone and
    motion streams' small values reach the backbone at the joints' scale), checked by hand."""
    model = _recognizer(input_norm=True).train()
    x = 0.01 * _two_bodies() + 0.5
    normalised = model.normalize(x)
    flat = x.reshape(-1, 25, 3)
    expected = (flat - flat.mean(0)) / torch.sqrt(flat.var(0, unbiased=False) + model.input_norm.eps)
    expected = expected * model.input_norm.weight.view(25, 3) + model.input_norm.bias.view(25, 3)
    torch.testing.assert_close(normalised.reshape(-1, 25, 3), expected, rtol=1e-9, atol=1e-9)
    assert _recognizer(input_norm=False).normalize(x) is x


def test_early_curve_counts_the_prediction_at_each_observed_fraction():
    curve = EarlyRecognitionCurve(fractions=(0.25, 0.5, 1.0))
    prob = torch.zeros(2, 8, 3)
    prob[0, :, 0] = 1  # sample 0: class 0 throughout
    prob[1, :4, 2] = 1  # sample 1: class 2 for frames 0-3, then class 1
    prob[1, 4:, 1] = 1
    curve.update(prob, torch.tensor([0, 1]))
    # Frames ceil(r * 8) - 1 = 1, 3, 7: sample 1 is right only at the last.
    torch.testing.assert_close(curve.compute(), torch.tensor([0.5, 0.5, 1.0]))
    assert [math.ceil(r * 8) - 1 for r in (0.25, 0.5, 1.0)] == [1, 3, 7]


def _sm(args, cwd) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "skeleton_mamba.tasks", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc


def test_causal_recipe_tests_with_an_early_curve_and_streams_a_skeleton(tmp_path):
    data = ["--data.init_args.train_per_class=4", "--data.init_args.val_per_class=2"]
    _sm(["fit", "--recipe", "recognition_synthetic_causal.yaml", "--trainer.max_epochs=1",
         "--trainer.enable_progress_bar=false", *data], tmp_path)  # fmt: skip
    ckpt = tmp_path / "runs/recognition_synthetic_causal/version_0/checkpoints/last.ckpt"
    proc = _sm(["test", "--recipe", "recognition_synthetic_causal.yaml", f"--ckpt_path={ckpt}",
                "--trainer.enable_progress_bar=false", *data], tmp_path)  # fmt: skip
    assert "early recognition, top-1" in proc.stdout + proc.stderr
    run = tmp_path / "runs/recognition_synthetic_causal/version_1"
    assert (run / "early_recognition.png").stat().st_size > 0
    rows = (run / "early_recognition.csv").read_text().splitlines()
    assert rows[0] == "observed_fraction,top1" and len(rows) == 11

    keypoint = make_synthetic_annotations(num_classes=3)["annotations"][0]["keypoint"][0]  # (T, 25, 3)
    np.save(tmp_path / "clip.npy", keypoint)
    args = ["stream", "--task", "recognition", "--ckpt", str(ckpt), "--skeleton", str(tmp_path / "clip.npy")]
    _sm([*args, "--out", str(tmp_path / "online")], tmp_path)
    lines = (tmp_path / "online" / "clip_online.csv").read_text().splitlines()
    assert len(lines) == 1 + keypoint.shape[0]
    probs = np.array([[float(v) for v in line.split(",")[2:]] for line in lines[1:]])
    np.testing.assert_allclose(probs.sum(axis=1), 1.0, atol=1e-5)
    assert (tmp_path / "online" / "clip_online.png").is_file()


def test_the_online_recognizer_streams_the_checkpoints_own_input_stream():
    """A bone checkpoint is fed bones (the same channel count as joints: nothing else would notice), a joint
    or old checkpoint joints; a motion stream, which needs the next frame, is refused."""
    from skeleton_mamba.tasks.recognition.online import _stream_features
    from skeleton_mamba.tasks.recognition.transforms import joint_to_bone

    joints = np.random.default_rng(0).normal(size=(2, 6, 25, 3)).astype(np.float32)
    bones = _stream_features(joints, {"datamodule_hyper_parameters": {"feats": ["b"]}}, "ntu25", "b.ckpt")
    np.testing.assert_allclose(bones, joint_to_bone(joints, "ntu25"), rtol=0, atol=1e-6)
    for old in ({}, {"datamodule_hyper_parameters": {"skeleton": "ntu25"}}):
        np.testing.assert_array_equal(_stream_features(joints, old, "ntu25", "j.ckpt"), joints)
    with pytest.raises(ValueError, match=r"jm.ckpt: trained on feats \['jm'\]; a motion stream needs"):
        _stream_features(joints, {"datamodule_hyper_parameters": {"feats": ["jm"]}}, "ntu25", "jm.ckpt")
