"""``--precision bf16`` of ``sm dance`` and ``sm stream`` (dance and online recognition) against fp32.

Each command runs twice on the same checkpoint and input, fp32 then bf16 (autocast: weights fp32,
projections in bf16, the SSD in fp32); the bf16 output must stay within the stated bound of the fp32 one
and differ from it (the option did take effect). The figures on trained demo checkpoints are in the
commands' help and in benchmarks/README.md; the bounds here are for the tiny random networks of the tests.
"""

from __future__ import annotations

import csv

import lightning
import numpy as np
import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

TINY = SkeletonMambaConfig(
    dim=16, depth=1, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
)
# Stated bounds for the tiny random networks: max |bf16 - fp32| over all joints and frames relative to the
# largest fp32 coordinate (random EMMs dance metres away: 0.054 measured); probabilities, absolute.
DANCE_RELATIVE = 0.1
STREAM_RELATIVE = 0.05  # 0.014 measured
ONLINE_PROBABILITY = 0.005  # 5.0e-4 measured


def _save(module, path, class_path: str):
    hparams = {**module.hparams, "_class_path": class_path}
    state = {"state_dict": module.state_dict(), "hyper_parameters": hparams}
    torch.save({**state, "pytorch-lightning_version": lightning.__version__}, path)
    return path


def _max_diff(a: np.ndarray, b: np.ndarray) -> float:
    assert a.shape == b.shape
    return float(np.abs(a - b).max())


def test_sm_dance_bf16_is_within_the_bound_of_fp32(tmp_path, tiny_egodance_module):
    from skeleton_mamba.tasks.egodance.dance_cli import main

    torch.manual_seed(0)
    module = tiny_egodance_module(use_head_estimator=False, head_source="none", use_vision=False)
    ckpt = _save(module, tmp_path / "emm.ckpt", "skeleton_mamba.tasks.egodance.module.EgoDanceModule")
    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 4.0))
    joints = {}
    for precision in ("fp32", "bf16"):
        out = tmp_path / precision
        args = ["--ckpt", str(ckpt), "--music", str(wav), "--out", str(out), "--no-render", "--steps", "2"]
        assert main([*args, "--precision", precision]) == 0
        joints[precision] = load_motion(out / "dance.npz").joints
    err = _max_diff(joints["bf16"], joints["fp32"]) / np.abs(joints["fp32"]).max()
    assert 0 < err <= DANCE_RELATIVE, err


def test_sm_dance_refuses_compile_with_bf16(tmp_path, tiny_egodance_module):
    from skeleton_mamba.errors import InputError
    from skeleton_mamba.tasks.egodance.dance_cli import main

    module = tiny_egodance_module(use_head_estimator=False, head_source="none", use_vision=False)
    ckpt = _save(module, tmp_path / "emm.ckpt", "skeleton_mamba.tasks.egodance.module.EgoDanceModule")
    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 1.0))
    args = ["--ckpt", str(ckpt), "--music", str(wav), "--out", str(tmp_path / "o"), "--no-render"]
    with pytest.raises(InputError, match="--compile runs the denoiser in fp32 only"):
        main([*args, "--compile", "--precision", "bf16"])


def test_sm_stream_bf16_dance_is_within_the_bound_of_fp32(tmp_path):
    from skeleton_mamba.tasks.stream.module import StreamDanceModule
    from skeleton_mamba.tasks.stream.stream_cli import main

    torch.manual_seed(0)
    module = StreamDanceModule(backbone=TINY)
    ckpt = _save(module, tmp_path / "stream.ckpt", "skeleton_mamba.tasks.stream.module.StreamDanceModule")
    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 2.0, sr=22050, seed=3))
    joints = {}
    for precision in ("fp32", "bf16"):
        out = tmp_path / precision
        args = ["--ckpt", str(ckpt), "--music", str(wav), "--out", str(out), "--no-render"]
        assert main([*args, "--precision", precision]) == 0
        joints[precision] = load_motion(out / "song.npz").joints
    err = _max_diff(joints["bf16"], joints["fp32"]) / np.abs(joints["fp32"]).max()
    assert 0 < err <= STREAM_RELATIVE, err


def test_sm_stream_recognition_bf16_probabilities_are_within_the_bound_of_fp32(tmp_path):
    from skeleton_mamba.tasks.recognition.module import ActionRecognitionModule
    from skeleton_mamba.tasks.recognition.online import main

    torch.manual_seed(0)
    backbone = SkeletonMambaConfig(skeleton="ntu25", in_channels=3, dim=16, depth=2, mlp_dim=32, causal=True,
                                   mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16))  # fmt: skip
    module = ActionRecognitionModule(backbone=backbone, num_classes=4)
    path = "skeleton_mamba.tasks.recognition.module.ActionRecognitionModule"
    ckpt = _save(module, tmp_path / "rec.ckpt", path)
    keypoints = tmp_path / "clip.npy"
    np.save(keypoints, np.random.default_rng(0).standard_normal((30, 25, 3)).astype(np.float32))
    probs = {}
    for precision in ("fp32", "bf16"):
        out = tmp_path / precision
        args = ["--ckpt", str(ckpt), "--skeleton", str(keypoints), "--out", str(out)]
        assert main([*args, "--precision", precision]) == 0
        with open(out / "clip_online.csv", newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))[1:]
        probs[precision] = np.array([[float(v) for v in row[2:]] for row in rows])
    assert np.allclose(probs["bf16"].sum(1), 1.0, atol=1e-5)  # fp32 probabilities
    err = _max_diff(probs["bf16"], probs["fp32"])
    assert 0 < err <= ONLINE_PROBABILITY, err
