"""QEAN through ``sm`` and the AIST++ data module on tiny generated data in the AIST++ layout."""

from __future__ import annotations

import pickle
from importlib.resources import files

import numpy as np
import pytest
import soundfile
import torch
from lightning.pytorch import Trainer

from skeleton_mamba.errors import DataFileError, DatasetNotFoundError
from skeleton_mamba.tasks.motion.formats.fact_features import smpl_to_features
from skeleton_mamba.tasks.motion.io.safe_pickle import safe_load_pickle
from skeleton_mamba.tasks.qean.data import AISTPPDanceDataModule
from skeleton_mamba.tasks.qean.model import QEANConfig
from skeleton_mamba.tasks.qean.module import QEANModule
from skeleton_mamba.tasks.training.lightning_cli import run
from tests.helpers.gltf_reader import glb_joint_positions

NAMES = ["gBR_sBM_cAll_d04_mBR0_ch01", "gPO_sBM_cAll_d10_mPO1_ch02", "gBR_sBM_cAll_d05_mBR0_ch03"]
TINY_NETWORK = {
    "hidden": 32, "heads": 2, "motion_layers": 1, "audio_layers": 1, "cross_layers": 1, "mlp_dim": 64,
    "num_periods": 2,
}  # fmt: skip
TINY_DATA = {"seed_frames": 12, "music_frames": 24, "predict_frames": 4, "generate_frames": 20}
TINY_MODEL = {
    "network": QEANConfig(**TINY_NETWORK, seed_frames=12, music_frames=24, predict_frames=4),
    "generate_frames": 20,
}


@pytest.fixture(scope="module")
def aistpp(tmp_path_factory):
    """motions/*.pkl (smpl_poses (N, 72) float32, smpl_trans, smpl_scaling) and music/<id>.wav, 1.2 s each."""
    root = tmp_path_factory.mktemp("aistpp")
    (root / "motions").mkdir()
    (root / "music").mkdir()
    rng = np.random.default_rng(0)
    for name in NAMES:
        n = 60 + 10 * NAMES.index(name)
        data = {
            "smpl_poses": (0.3 * rng.normal(size=(n, 72))).astype(np.float32),
            "smpl_trans": rng.normal(size=(n, 3)).astype(np.float32) * 90.0,
            "smpl_scaling": np.array([90.0], dtype=np.float32),
        }
        with open(root / "motions" / f"{name}.pkl", "wb") as f:
            pickle.dump(data, f)
    sr = 22050
    t = np.arange(int(1.2 * sr)) / sr
    for mid in ("mBR0", "mPO1"):
        clicks = (np.sin(2 * np.pi * 440 * t) * (np.mod(t, 0.5) < 0.05)).astype(np.float32)
        soundfile.write(root / "music" / f"{mid}.wav", clicks, sr)
    (root / "train.txt").write_text("\n".join(NAMES[:2]) + "\n")
    (root / "test.txt").write_text("\n".join(NAMES[1:]) + "\n")
    return root


def _data(root, **kw) -> AISTPPDanceDataModule:
    args = dict(TINY_DATA, train_split=str(root / "train.txt"), test_split=str(root / "test.txt"))
    args.update(
        music_cache_dir=str(root / "cache"),
        batch_size=2,
        num_workers=0,
        reference_splits=[args["train_split"]],
    )
    return AISTPPDanceDataModule(str(root), **(args | kw))


def test_data_module_windows_match_the_files(aistpp):
    dm = _data(aistpp)
    dm.setup("fit")
    item = dm.datasets["train"][0]
    assert (
        item["motion"].shape == (12, 219)
        and item["music"].shape == (24, 35)
        and item["target"].shape == (4, 219)
    )
    raw = safe_load_pickle(aistpp / "motions" / f"{NAMES[0]}.pkl")
    poses = torch.from_numpy(raw["smpl_poses"]).double().reshape(-1, 24, 3)
    expected = smpl_to_features(poses, torch.from_numpy(raw["smpl_trans"]).double() / 90.0)
    torch.testing.assert_close(item["motion"].double(), expected[:12], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(item["target"].double(), expected[12:16], atol=1e-5, rtol=1e-5)
    # windows per sequence: min(motion - 16, music - 24) + 1, music has 1 + 1.2 s * 30720 // 512 = 73 frames
    music_len = dm.sequence(NAMES[0])[1].shape[0]
    assert music_len == 1 + int(1.2 * 30720) // 512
    assert len(dm.datasets["train"]) == sum(min(n - 16, music_len - 24) + 1 for n in (60, 70))


def test_data_module_reports_missing_layout(tmp_path):
    with pytest.raises(DatasetNotFoundError, match="motions"):
        AISTPPDanceDataModule(str(tmp_path))
    (tmp_path / "motions").mkdir()
    with pytest.raises(DatasetNotFoundError, match="music"):
        AISTPPDanceDataModule(str(tmp_path))


def test_test_splits_come_from_the_annotations_val_plus_test(aistpp, tmp_path):
    root = tmp_path / "annotations"
    (root / "splits").mkdir(parents=True)
    for folder in ("motions", "music"):
        (root / folder).symlink_to(aistpp / folder)
    dm = AISTPPDanceDataModule(str(root), music_cache_dir=str(aistpp / "cache"), num_workers=0, **TINY_DATA)
    assert dm.test_splits == ["val", "test"]  # default: [QEAN]'s 40 = crossmodal val + test
    with pytest.raises(FileNotFoundError, match="crossmodal_val.txt"):
        dm.split_names("val")
    packaged = files("skeleton_mamba.tasks.motion.formats") / "aistpp_splits" / "crossmodal_test.txt"
    lines = [n for n in packaged.read_text().split() if n.startswith("g")]  # the file's own text
    assert dm.split_names("test") == lines and len(lines) == 20 and "gLH_sBM_cAll_d17_mLH4_ch02" in lines
    (root / "splits" / "crossmodal_val.txt").write_text(f"# val\n{NAMES[0]}\n")
    (root / "splits" / "crossmodal_test.txt").write_text(f"{NAMES[1]}\n{NAMES[2]}\n{NAMES[0]}\n")
    dm.setup("test")
    assert [item["name"] for item in dm.datasets["test"]] == NAMES  # val then test, each sequence once
    limited = AISTPPDanceDataModule(
        str(root), music_cache_dir=str(aistpp / "cache"), test_max_sequences=2, **TINY_DATA
    )
    limited.setup("test")
    assert [item["name"] for item in limited.datasets["test"]] == NAMES[:2]


def test_results_table_says_whether_it_is_the_paper_protocol():
    module = QEANModule(**(TINY_MODEL | {"generate_frames": 1200}))
    values = {"FID_k": 1.0, "FID_g": 2.0, "Dist_k": 3.0, "Dist_g": 4.0, "BeatAlign": 0.25}
    module._generated_count, module._reference_count = 40, 1363
    table = module.results_table(values)
    assert "paper protocol" in table and "NOT COMPARABLE" not in table
    import librosa
    import numpy

    assert f"audio stack: librosa {librosa.__version__}, numpy {numpy.__version__}, soundfile " in table
    assert "FID_k           1.000         30.1          -" in table
    assert "BeatAlign       0.250        0.239      0.292" in table
    module._generated_count = 20
    assert "NOT COMPARABLE with [QEAN] Table 1: 20 sequences instead of 40" in module.results_table(values)
    # one generated sequence: FID and Dist are not defined; the table says so instead of failing
    module._generated_count = 1
    table = module.results_table({"BeatAlign": 0.25})
    assert "FID and Dist need at least 2 generated sequences (1 scored)" in table and "FID_k " not in table
    module.test_evaluation.add(torch.zeros(150, 24, 3, dtype=torch.float64), 60.0, real=True)
    module.test_evaluation.add(torch.zeros(150, 24, 3, dtype=torch.float64), 60.0, real=True)
    module.test_evaluation.add(torch.randn(150, 24, 3, dtype=torch.float64), 60.0, np.array([30, 60]))
    assert set(module.test_scores()) == {"BeatAlign"}


def test_test_metrics_and_predict(aistpp, tmp_path):
    torch.manual_seed(0)
    module = QEANModule(**TINY_MODEL, output_dir=str(tmp_path / "out"), render=True)
    trainer = Trainer(accelerator="cpu", logger=False, enable_progress_bar=False, enable_checkpointing=False)
    results = trainer.test(module, datamodule=_data(aistpp), verbose=False)[0]
    for name in ("FID_k", "FID_g", "Dist_k", "Dist_g", "BeatAlign"):
        assert np.isfinite(results[f"test/{name}"]), name
    assert 0.0 <= results["test/BeatAlign"] <= 1.0
    dm = _data(
        aistpp,
        predict_seed=str(aistpp / "motions" / f"{NAMES[0]}.pkl"),
        predict_music=str(aistpp / "music" / "mBR0.wav"),
    )
    paths = {p.suffix: p for p in trainer.predict(module, datamodule=dm)[0]}
    assert sorted(paths) == [".bvh", ".glb", ".mp4", ".npz", ".wav"]
    with np.load(paths[".npz"], allow_pickle=False) as saved:
        # the whole 1.2 s song at 60 fps (librosa's centred frames: one more), not generate_frames = 20
        assert saved["smpl_poses"].shape == (73, 72) and saved["joints"].shape == (73, 24, 3)
        assert float(saved["fps"]) == 60.0
        joints = saved["joints"]
    assert paths[".mp4"].stat().st_size > 0  # rendered with the music's slice (.wav)
    # The .glb re-read with an independent reader reproduces the dance's joints.
    _, glb_joints = glb_joint_positions(paths[".glb"])
    np.testing.assert_allclose(glb_joints, joints, atol=1e-5)


def test_sm_fit_one_training_step(aistpp, tmp_path, monkeypatch, caplog):
    """``sm fit --recipe qean.yaml`` in this process (the subprocess path is
    tests/tasks/qean/test_qean_sm.py's)."""
    model_args = [f"--model.init_args.network.{k}={v}" for k, v in TINY_NETWORK.items()]
    data_args = [f"--data.init_args.{k}={v}" for k, v in TINY_DATA.items()]
    argv = [
        "fit", "--recipe", "qean.yaml",
        "--trainer.fast_dev_run", "1", "--trainer.accelerator", "cpu", "--trainer.logger", "false",
        "--trainer.callbacks", "null", "--trainer.enable_progress_bar", "false",
        f"--data.init_args.root={aistpp}", f"--data.init_args.train_split={aistpp / 'train.txt'}",
        f"--data.init_args.music_cache_dir={aistpp / 'cache'}", "--data.init_args.batch_size=2",
        "--data.init_args.num_workers=0", *model_args, *data_args,
    ]  # fmt: skip
    monkeypatch.chdir(tmp_path)
    caplog.set_level("INFO")
    losses, log = [], QEANModule.log

    def record(self, name, value, *args, **kwargs):
        losses.append((name, float(value)))
        return log(self, name, value, *args, **kwargs)

    monkeypatch.setattr(QEANModule, "log", record)
    assert run(argv) == 0
    assert "`max_steps=1` reached" in caplog.text  # fast_dev_run: exactly one training step
    assert len(losses) == 1 and losses[0][0] == "train/loss" and np.isfinite(losses[0][1])  # its L2 loss


def test_test_loop_under_the_bailando_protocol(aistpp, caplog):
    torch.manual_seed(0)
    module = QEANModule(**TINY_MODEL, protocol="bailando")
    trainer = Trainer(accelerator="cpu", logger=False, enable_progress_bar=False, enable_checkpointing=False)
    with caplog.at_level("INFO"):
        results = trainer.test(module, datamodule=_data(aistpp), verbose=False)[0]
    assert 0.0 <= results["test/BeatAlign"] <= 1.0 and np.isfinite(results["test/FID_k"])
    table = module.results_table({"FID_k": 1.0, "BeatAlign": 0.2})
    assert "protocol bailando:" in table and "protocol bailando ([QEAN] Table 1 follows FACT's)" in table
    with pytest.raises(ValueError, match="fact, bailando, edge"):
        QEANModule(**TINY_MODEL, protocol="lodge")


def test_predict_refuses_music_no_longer_than_the_seed(aistpp, tmp_path):
    """``sm predict`` dances the whole song after the seed: a track within the seed's 0.2 s has nothing to
    dance, and says so naming the file."""
    short = tmp_path / "short.wav"
    soundfile.write(short, np.zeros(2205, dtype=np.float32), 22050)  # 0.1 s
    dm = _data(aistpp, predict_seed=str(aistpp / "motions" / f"{NAMES[0]}.pkl"), predict_music=str(short))
    with pytest.raises(
        DataFileError, match=r"short\.wav: 0\.1\d s of music, no longer than the 12-frame seed"
    ):
        dm.setup("predict")
