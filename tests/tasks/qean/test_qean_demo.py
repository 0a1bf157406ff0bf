"""The QEAN demo: ``sm fit --recipe qean_demo.yaml`` writes the SYNTHETIC AIST++-layout set on first use,
trains QEAN on it and, when fit ends, :class:`~skeleton_mamba.tasks.qean.demo.QEANDemo` generates from the
held-out seeds and music, prints the protocol table (NOT COMPARABLE with [QEAN] Table 1) and the dynamics
checks, and writes the dance, its ground truth, ``demo.json`` and ``view.html``. The demo's QEAN learns."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
import yaml

from skeleton_mamba.tasks.motion.formats.fact_features import features_to_joints
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.metrics.beat_conditioning import margin_over_chance
from skeleton_mamba.tasks.motion.music.features import BEAT
from skeleton_mamba.tasks.qean.data import AISTPPDanceDataModule
from skeleton_mamba.tasks.qean.model import QEANConfig
from skeleton_mamba.tasks.qean.module import QEANModule
from skeleton_mamba.tasks.training.cli import main as sm_main
from skeleton_mamba.tasks.training.recipe_resolution import packaged_recipes

LENGTHS = {"seed_frames": 12, "music_frames": 24, "predict_frames": 4, "generate_frames": 72}
TINY = [
    "--trainer.max_steps=3", "--trainer.enable_progress_bar=false", "--data.init_args.synthetic_count=4",
    "--data.init_args.synthetic_held_out=2", "--data.init_args.synthetic_duration_s=1.5",
    "--data.init_args.batch_size=2", "--data.init_args.window_stride=4", "--data.init_args.rollout_frames=2",
    "--model.init_args.network.hidden=16", "--model.init_args.network.heads=2",
    "--model.init_args.network.mlp_dim=32", "--model.init_args.network.cross_layers=1",
    *(f"--data.init_args.{k}={v}" for k, v in LENGTHS.items()),
]  # fmt: skip


def _recipe() -> dict:
    return yaml.safe_load(Path(packaged_recipes()["qean_demo.yaml"]).read_text(encoding="utf-8"))


@pytest.mark.slow  # about 30 s of CPU (a 4-dance set, 3 steps, 72 generated frames, rendering off)
def test_qean_demo_runs_end_to_end_and_writes_its_files(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    callbacks = [
        {"class_path": "lightning.pytorch.callbacks.ModelCheckpoint", "init_args": {"filename": "last"}},
        {"class_path": "skeleton_mamba.tasks.qean.demo.QEANDemo", "init_args": {"render": False}},
    ]
    root = tmp_path / "data"
    args = ["fit", "--recipe", "qean_demo.yaml", *TINY, f"--data.init_args.root={root}"]
    assert sm_main([*args, "--trainer.callbacks", json.dumps(callbacks)]) == 0
    # the SYNTHETIC set, written on first use: 2 training dances, 2 held out (FID needs 2 generated sequences)
    assert "SYNTHETIC" in (root / "SYNTHETIC.txt").read_text()
    assert len((root / "splits" / "crossmodal_train.txt").read_text().split()) == 2
    held_out = (root / "splits" / "crossmodal_val.txt").read_text().split()
    assert len(held_out) == 2
    folder = Path("runs/qean_demo/version_0/demo")
    demo = json.loads((folder / "demo.json").read_text())
    assert demo["synthetic"] is True and "SYNTHETIC" in demo["label"] and demo["global_step"] == 3
    assert demo["frames"] == {"seed": 12, "music": 24, "predict": 4, "generate": 72}
    protocol = demo["protocol"]
    assert protocol["comparable_with_paper"] is False and protocol["sequences"] == 2
    assert {"FID_k", "FID_g", "Dist_k", "Dist_g", "BeatAlign"} <= set(protocol)
    assert 0 <= protocol["BeatAlign"] <= 1 and protocol["Dist_k"] >= 0
    columns = {c: m for c, m in demo["scores"].items() if isinstance(m, dict)}
    assert columns["ground_truth"] == pytest.approx(
        {"amplitude_ratio": 1, "jitter_ratio": 1, "high_frequency_ratio": 1}
    )
    assert columns["mean_pose"] == pytest.approx({k: 0 for k in columns["ground_truth"]})
    assert all(math.isfinite(v) and v >= 0 for v in columns["dance"].values())
    assert set(demo["checks"]) == {
        "amplitude ratio >= 0.7",
        "jitter ratio <= 1.5",
        "energy above 6 Hz within 2x of the ground truth's",
    }
    (sample,) = demo["samples"]
    assert sample["sequence"] == held_out[0]
    dance, reference = (load_motion(sample[k]["npz"]) for k in ("dance", "reference"))
    assert dance.num_frames == reference.num_frames == 12 + 72
    # the dance starts from the held-out sequence's own seed: its first 12 frames are the truth's
    np.testing.assert_allclose(dance.joints[:12], reference.joints[:12], atol=1e-5)
    assert not np.allclose(dance.joints[12:], reference.joints[12:], atol=1e-3)
    assert set(sample["dance"]) == {"npz", "bvh", "glb"}  # render off: no mp4, and no music slice for it
    assert all(Path(p).stat().st_size > 0 for p in sample["dance"].values())
    # the reference is the truth: the held-out sequence's joints from the data module's own reader
    data = AISTPPDanceDataModule(root=str(root), synthetic=True, **LENGTHS)
    truth = features_to_joints(data.sequence(held_out[0])[0][:84].double()).numpy()
    np.testing.assert_allclose(reference.joints, truth, atol=1e-4)
    out = capsys.readouterr().out
    assert "NOT COMPARABLE with [QEAN] Table 1: synthetic data in the AIST++ layout" in out
    assert f"{'BeatAlign':<10} {protocol['BeatAlign']:>10.3f}" in out
    for check, ok in demo["checks"].items():
        assert f"{'reached' if ok else 'NOT reached'}: {check}" in out
    # the conditioning: the generated frames' beat margin over chance beside the truth's, on the music's beats
    conditioning = demo["conditioning"]
    truths = [features_to_joints(data.sequence(n)[0][12:84].double()).numpy() for n in held_out]
    beats = [np.flatnonzero(data.sequence(n)[1][12:84, BEAT].numpy() > 0.5) for n in held_out]
    expected = [margin_over_chance(t, b, 60.0) for t, b in zip(truths, beats)]
    assert conditioning["truth_per_sequence"] == pytest.approx(expected, abs=1e-6, nan_ok=True)
    assert any(math.isfinite(m) for m in expected)  # a sequence with fewer than 2 beats has no chance: NaN
    assert conditioning["margin"] == pytest.approx(np.nanmean(conditioning["per_sequence"]))
    assert f"dance {conditioning['margin']:+.3f}, ground truth {conditioning['truth_margin']:+.3f}" in out
    verdict = "reached" if conditioning["reached"] else "NOT reached"
    assert f"{verdict}: beat margin over chance >= 0.5 x the ground truth's" in out
    page = (folder / "view.html").read_text()
    assert f"viewer: {folder / 'view.html'}" in out and "dance" in page and "reference" in page


def test_demo_recipe_is_a_small_qean_on_the_synthetic_set():
    recipe = _recipe()
    data, network = recipe["data"]["init_args"], recipe["model"]["init_args"]["network"]
    assert data["synthetic"] is True and data["root"] == "runs/qean_demo/data" and data["test_split"] == "val"
    assert network["hidden"] < QEANConfig.hidden and "max_time" not in recipe["trainer"]
    callbacks = [c["class_path"] for c in recipe["trainer"]["callbacks"]]
    assert "skeleton_mamba.tasks.qean.demo.QEANDemo" in callbacks
    # against trembling and freezing: the output low-pass and rollouts of the seed's last 20 frames
    assert network["smoothing_stages"] == 8 and network["smoothing_decay"] == 0.6
    assert recipe["model"]["init_args"]["rollout_probability"] == 1.0 and data["rollout_frames"] == 20


def test_the_demo_qean_overfits_two_windows(tmp_path):
    """The recipe's network and window lengths on two windows of the synthetic set: the loss falls 20-fold."""
    recipe = _recipe()
    data_args = recipe["data"]["init_args"]
    lengths = {k: data_args[k] for k in ("seed_frames", "music_frames", "predict_frames")}
    data = AISTPPDanceDataModule(
        root=str(tmp_path / "data"),
        synthetic=True,
        synthetic_count=2,
        synthetic_held_out=1,
        synthetic_duration_s=3.5,
        window_stride=50,
        num_workers=0,
        **lengths,
    )
    data.setup("fit")
    windows = [data.datasets["train"][i] for i in range(2)]
    batch = {k: torch.stack([w[k] for w in windows]) for k in ("motion", "music", "target")}
    torch.manual_seed(0)
    network = QEANConfig(**{**recipe["model"]["init_args"]["network"], **lengths, "dropout": 0.0})
    module = QEANModule(network=network, lr=1e-3)
    optimizer = torch.optim.Adam(module.parameters(), lr=1e-3)
    losses = []
    for _ in range(150):
        optimizer.zero_grad()
        loss = F.mse_loss(module(batch["motion"], batch["music"]), batch["target"])
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert losses[-1] < losses[0] / 20


def test_rollout_windows_carry_the_earlier_frames_and_the_seed_ends_in_the_models_own():
    """rollout_frames R: the window starts R frames earlier (motion R + S, music R + M, the same target);
    rollout_probability 1: the seed's last R frames are the network's prediction from the seed R frames
    earlier, written out here with the network itself; 0 (and eval mode): the true last S frames."""
    from skeleton_mamba.tasks.qean.data import DanceWindowDataset

    torch.manual_seed(0)
    motion, music = torch.randn(50, 219), torch.randn(50, 35)
    plain = DanceWindowDataset({"a": (motion, music)}, 12, 16, 4, stride=5)
    rolled = DanceWindowDataset({"a": (motion, music)}, 12, 16, 4, stride=5, rollout_frames=3)
    item = rolled[1]  # the window starting at 5: seed [8, 20), target [20, 24)
    torch.testing.assert_close(item["motion"], motion[5:20])
    torch.testing.assert_close(item["music"], music[5:24])
    torch.testing.assert_close(item["target"], motion[20:24])
    assert len(rolled) == len(range(0, 50 - 15 - 4 + 1, 5))  # windows of 15 + 4 frames in 50
    assert len(plain) == len(range(0, 50 - 12 - 4 + 1, 5))

    sizes = dict(hidden=16, heads=2, motion_layers=1, audio_layers=1, cross_layers=1, mlp_dim=32, dropout=0.0)
    network = QEANConfig(**sizes, seed_frames=12, music_frames=16, predict_frames=4)
    batch_motion = torch.stack([rolled[i]["motion"] for i in range(3)])
    batch_music = torch.stack([rolled[i]["music"] for i in range(3)])
    always = QEANModule(network=network, rollout_probability=1.0).train()
    seed, future_music = always.rollout_seed(batch_motion, batch_music)
    with torch.no_grad():
        own = always.model(batch_motion[:, :12], batch_music[:, :16])[:, :3]
    torch.testing.assert_close(seed, torch.cat([batch_motion[:, 3:12], own], dim=1))
    torch.testing.assert_close(future_music, batch_music[:, 3:])
    assert not seed.requires_grad  # no gradient through the rolled-out frames
    never = QEANModule(network=network).train()
    assert never.hparams.rollout_probability == 0  # [QEAN]'s teacher forcing is the default
    torch.testing.assert_close(never.rollout_seed(batch_motion, batch_music)[0], batch_motion[:, 3:])
    torch.testing.assert_close(always.eval().rollout_seed(batch_motion, batch_music)[0], batch_motion[:, 3:])
    with pytest.raises(ValueError, match="rollout_probability"):
        QEANModule(network=network, rollout_probability=1.5)
    with pytest.raises(ValueError, match="rollout_frames must be 0 to 12"):
        AISTPPDanceDataModule(root="x", synthetic=True, seed_frames=12, predict_frames=4, rollout_frames=13)


def test_a_rollout_longer_than_one_prediction_chains_them_into_a_seed_all_its_own():
    """R = S = 12 with P = 4: three predictions, each from the seed the previous ones left (frames
    [4k, 12 + 4k) and music [4k, 16 + 4k)), written out step by step; the seed is then all the network's."""
    torch.manual_seed(1)
    sizes = dict(hidden=16, heads=2, motion_layers=1, audio_layers=1, cross_layers=1, mlp_dim=32, dropout=0.0)
    network = QEANConfig(**sizes, seed_frames=12, music_frames=16, predict_frames=4)
    module = QEANModule(network=network, rollout_probability=1.0).train()
    motion, music = torch.randn(2, 24, 219), torch.randn(2, 28, 35)  # R + S frames, R + M music frames
    seed, future_music = module.rollout_seed(motion, music)
    expected = motion.clone()
    with torch.no_grad():
        for k in range(3):
            own = module.model(expected[:, 4 * k : 12 + 4 * k], music[:, 4 * k : 16 + 4 * k])
            expected[:, 12 + 4 * k : 16 + 4 * k] = own
    torch.testing.assert_close(seed, expected[:, 12:])
    torch.testing.assert_close(future_music, music[:, 12:])
    assert not torch.isclose(seed, motion[:, 12:]).any()  # no true frame is left in the seed
    # a rollout of 6 frames: one full prediction and 2 frames of the next
    six, _ = module.rollout_seed(motion[:, 6:], music[:, 6:])
    partial = motion[:, 6:].clone()
    with torch.no_grad():
        partial[:, 12:16] = module.model(partial[:, :12], music[:, 6:22])
        partial[:, 16:18] = module.model(partial[:, 4:16], music[:, 10:26])[:, :2]
    torch.testing.assert_close(six, partial[:, 6:])
