"""EgoDance LightningModule and data module; the demo recipe through the real ``sm`` entry point."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from lightning.pytorch import Trainer
from lightning.pytorch.loggers import Logger
from torch.utils.data import DataLoader

from skeleton_mamba.errors import DatasetNotFoundError, InputError
from skeleton_mamba.tasks.egodance.data import EgoDanceDataModule, assign_splits
from skeleton_mamba.tasks.egodance.representation import encode_motion
from skeleton_mamba.tasks.motion.music.features import audio_stack


def test_data_module_explains_what_is_missing(tmp_path):
    with pytest.raises(DatasetNotFoundError, match="sm make-ego"):
        EgoDanceDataModule(str(tmp_path / "nowhere")).check_data()
    (tmp_path / "ego" / "samples" / "half_written").mkdir(parents=True)
    with pytest.raises(DatasetNotFoundError, match="no complete sample"):
        EgoDanceDataModule(str(tmp_path / "ego")).check_data()


def test_splits_keep_sources_together_and_respect_aist_test_list():
    split = assign_splits([f"m/dance{i}.npz" for i in range(10)], 0.2, 0.1)
    assert sorted(split.values()).count("val") == 2 and sorted(split.values()).count("test") == 1
    aist = assign_splits(["gBR_sBM_cAll_d04_mBR0_ch02.pkl", "gBR_sBM_cAll_d04_mBR0_ch01.pkl"], 0.0, 0.5)
    assert aist == {"gBR_sBM_cAll_d04_mBR0_ch02.pkl": "test", "gBR_sBM_cAll_d04_mBR0_ch01.pkl": "train"}


def test_canonicalize_init_head_turns_each_window_to_face_its_first_head_heading(tmp_path):
    from skeleton_mamba.tasks.egodance.data import SyntheticEgoDanceDataModule
    from skeleton_mamba.tasks.egodance.representation import HEAD_JOINT, motion_joints

    kwargs = dict(root=str(tmp_path / "data"), count=2, duration_s=5.0, frame_size=16, image_size=16,
                  val_fraction=0.0, test_fraction=0.0, music_cache_dir=str(tmp_path / "cache"))  # fmt: skip
    world = SyntheticEgoDanceDataModule(**kwargs)
    world.prepare_data()
    world.setup("fit")
    canon = SyntheticEgoDanceDataModule(**kwargs, canonicalize_init_head=True)
    canon.setup("fit")
    for w, c in zip(world.datasets["train"].items, canon.datasets["train"].items, strict=True):
        # the head faces +z in frame 0 (its forward axis: the rotation's third column), pitch kept
        forward_w, forward_c = w["head_rotation"][0, :, 2].double(), c["head_rotation"][0, :, 2].double()
        assert abs(forward_c[0]) < 1e-6 and forward_c[2] > 0
        assert forward_c[1] == pytest.approx(float(forward_w[1]), abs=1e-6)
        # the whole window is the world-yaw window turned by minus that heading about the vertical through
        # the root's start (floor and root start unchanged), motion and head targets alike
        angle = -float(np.arctan2(forward_w[0], forward_w[2]))
        c_, s_ = np.cos(angle), np.sin(angle)
        turn = torch.tensor([[c_, 0, s_], [0, 1, 0], [-s_, 0, c_]])
        joints_w, joints_c = motion_joints(w["motion"]).double(), motion_joints(c["motion"]).double()
        start = joints_w[0, 0] * torch.tensor([1.0, 0.0, 1.0], dtype=torch.float64)
        torch.testing.assert_close(joints_c, (joints_w - start) @ turn.T, atol=1e-4, rtol=0)
        head_w = w["head"].double()
        torch.testing.assert_close(c["head"].double(), (head_w - start) @ turn.T, atol=1e-4, rtol=0)
        torch.testing.assert_close(c["head"], motion_joints(c["motion"])[:, HEAD_JOINT], atol=1e-4, rtol=0)
        torch.testing.assert_close(c["head_rotation"].double(), turn @ w["head_rotation"].double())
        torch.testing.assert_close(c["music"], w["music"])


def test_synthetic_set_refuses_dances_generated_with_other_settings(tmp_path):
    from skeleton_mamba.tasks.egodance.data import SyntheticEgoDanceDataModule

    motions = tmp_path / "data" / "motions"
    motions.mkdir(parents=True)
    (motions / "synthetic_bounce_120bpm_s0.npz").write_bytes(b"")
    module = SyntheticEgoDanceDataModule(root=str(tmp_path / "data"), count=2, swing_side="music")
    with pytest.raises(ValueError, match="unrecorded settings.*remove"):  # a build from before the record
        module.prepare_data()
    settings = {"count": 2, "duration_s": 10.0, "seed": 0, "fps": 30.0, "swing_side": "random"}
    (motions / "generator.json").write_text(json.dumps(settings))
    with pytest.raises(ValueError, match="'swing_side': 'random'.*'swing_side': 'music'"):
        module.prepare_data()


@pytest.fixture(scope="module")
def song(tmp_path_factory) -> str:
    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

    return str(write_music(tmp_path_factory.mktemp("music") / "song.wav", synthesize_music(120.0, 6.0)))


def _batches(song: str, n: int = 2, t: int = 16) -> list[dict]:
    gen = torch.Generator().manual_seed(0)
    motion = encode_motion(
        0.2 * torch.randn(n, t, 24, 3, generator=gen), 0.1 * torch.randn(n, t, 3, generator=gen)
    )
    music = torch.randn(n, t, 35, generator=gen)
    music[..., 34] = (torch.arange(t) % 8 == 0).float()
    return [
        {
            "sample_id": f"s{i}",
            "motion": motion[i],
            "music": music[i],
            "frames": torch.rand(t, 3, 32, 32, generator=gen),
            "head": torch.zeros(t, 3),
            "music_path": song,
            "music_start_s": 0.5 * i,
            "head_rotation": torch.eye(3).expand(t, 3, 3),
        }
        for i in range(n)
    ]


def test_test_loop_under_the_edge_protocol(tmp_path, tiny_egodance_module, song):
    """Default protocol ``edge``: 150-frame windows, each with its own 5 s music slice; PFC reported."""
    torch.manual_seed(0)
    module = tiny_egodance_module(sampling_steps=2)
    assert module.test_evaluations["estimated_head"].protocol.name == "edge"
    trainer = Trainer(accelerator="cpu", logger=False, enable_checkpointing=False, enable_progress_bar=False,
                      enable_model_summary=False, default_root_dir=tmp_path)  # fmt: skip
    results = trainer.test(module, DataLoader(_batches(song, t=150), batch_size=2), verbose=False)[0]
    for source in ("estimated_head", "oracle_head"):
        assert results[f"test/{source}/pfc"] >= 0 and 0 <= results[f"test/{source}/beat_align"] <= 1
        assert np.isfinite(results[f"test/{source}/FID_k"]) and np.isfinite(results[f"test/{source}/Div_g"])


class _HyperparameterRecorder(Logger):
    name, version = "recorder", 0

    def __init__(self):
        super().__init__()
        self.logged = []

    def log_metrics(self, metrics, step=None):
        pass

    def log_hyperparams(self, params, *args, **kwargs):
        self.logged.append(params)


def test_module_trains_tests_and_predicts(tmp_path, tiny_egodance_module, song, capsys):
    torch.manual_seed(0)
    module = tiny_egodance_module(sampling_steps=3, ema_every=1, protocol="bailando")  # 16-frame windows
    loader = DataLoader(_batches(song), batch_size=2)
    trainer = Trainer(
        accelerator="cpu",
        max_steps=2,
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        default_root_dir=tmp_path,
    )
    before = [p.detach().clone() for p in module.ema.module.parameters()]
    trainer.fit(module, loader, loader)
    assert any(not torch.equal(a, b) for a, b in zip(before, module.ema.module.parameters(), strict=True))
    trainer.loggers = [recorder := _HyperparameterRecorder()]
    results = trainer.test(module, loader, verbose=False)[0]
    assert {"audio_stack": audio_stack()} in recorder.logged  # the versions that decide the beats
    # (PFC belongs to the edge protocol: tested above)
    names = ("mpjpe_mm", "root_error_mm", "head_error_mm", "beat_align", "mmv", "mm", "mv", "FID_k")
    for source in ("estimated_head", "oracle_head"):  # the default (estimate) and the oracle comparison
        for name in names:
            key = f"test/{source}/{name}"
            assert key in results and results[key] == results[key]  # present and not NaN
        assert results[f"test/{source}/mpjpe_mm"] > 0
    for key in ("test/head_estimator/position_mm", "test/head_estimator/rotation_deg"):
        assert key in results and results[key] > 0
    out = trainer.predict(module, loader)[0]
    assert out["tokens"].shape == (2, 16, 24, 10) and out["joints"].shape == (2, 16, 24, 3)

    # `sm dance` on a checkpoint of this module: a 2 s track and video, long-form windows of 16 frames
    import imageio.v3 as iio

    from skeleton_mamba.tasks.egodance.dance_cli import main as dance_main
    from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

    trainer.save_checkpoint(tmp_path / "emm.ckpt")
    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 2.0))
    iio.imwrite(
        tmp_path / "ego.mp4",
        (np.random.default_rng(0).random((60, 32, 32, 3)) * 255).astype(np.uint8),
        fps=30,
    )
    args = [
        "--ckpt",
        str(tmp_path / "emm.ckpt"),
        "--music",
        str(wav),
        "--video",
        str(tmp_path / "ego.mp4"),
        "--out",
        str(tmp_path / "dance.npz"),
        "--steps",
        "2",
        "--window",
        "16",
        "--overlap",
        "8",
        "--no-render",
    ]
    assert dance_main(args) == 0
    assert "head trajectory estimated from the video" in capsys.readouterr().out  # the default head source
    with pytest.raises(InputError, match="--head oracle needs the ground-truth camera path"):
        dance_main([*args, "--head", "oracle"])
    dance = load_motion(tmp_path / "dance.npz")
    assert (tmp_path / "dance.bvh").is_file() and not (tmp_path / "dance.mp4").exists()
    assert dance.poses.shape == (60, 24, 3) and np.isfinite(dance.joints).all()


def _audio_streams(path) -> int:
    """Audio streams of a media file, as the ffmpeg binary of imageio-ffmpeg reports them."""
    import imageio_ffmpeg

    probe = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True, text=True
    )
    return sum(" Audio: " in line for line in probe.stderr.splitlines())


def test_demo_recipe_through_sm(tmp_path):
    sm = Path(sys.executable).with_name("sm")
    if not sm.exists():
        pytest.skip(f"console script not installed at {sm}")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "ignore"}
    args = [
        str(sm), "fit", "--recipe", "egodance_demo.yaml", "--trainer.max_steps", "2",
        "--trainer.log_every_n_steps", "1", "--trainer.limit_val_batches", "0",
        "--data.init_args.count", "7", "--data.init_args.duration_s", "5",
        "--data.init_args.frame_size", "32", "--data.init_args.image_size", "32",
        "--model.init_args.image_size", "32", "--data.init_args.val_fraction", "0",
        "--data.init_args.test_fraction", "0.1", "--data.init_args.music_cache_dir", str(tmp_path / "cache"),
        "--model.init_args.sampling.sampling_steps", "2",
    ]  # fmt: skip
    proc = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert len(list((tmp_path / "runs/egodance_demo/data/ego/samples").iterdir())) == 7
    run = tmp_path / "runs/egodance_demo/version_0"
    assert (run / "checkpoints/last.ckpt").is_file()
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    losses = [float(r["train/loss"]) for r in rows if r.get("train/loss")]
    assert len(losses) == 2 and all(v == v and v > 0 for v in losses)
    aligns = [float(r["train/align"]) for r in rows if r.get("train/align")]
    assert len(aligns) == 2 and all(v > 0 for v in aligns)  # the alignment loss is part of training

    # the DanceDemo callback: the held-out window (arms, middle tempo: the stratified split) danced,
    # written as npz + bvh + mp4, labelled
    import imageio.v3 as iio

    from skeleton_mamba.tasks.motion.formats.bvh import load_bvh
    from skeleton_mamba.tasks.motion.formats.motion_file import load_motion

    demo = run / "demo"
    summary = json.loads((demo / "demo.json").read_text())
    assert summary["synthetic"] is True and summary["held_out_split"] == "test"
    assert summary["samples"][0]["sample_id"].startswith("synthetic_arms_103bpm_s3")  # 93 < 103 < 133 bpm
    files = {k: tmp_path / v for k, v in summary["samples"][0]["dance"].items()}
    assert all(Path(files[k]).name.startswith("synthetic_") for k in ("npz", "bvh", "mp4"))
    assert "SYNTHETIC" in proc.stdout and str(Path(files["mp4"]).name) in proc.stdout
    motion = load_motion(files["npz"])
    assert motion.poses.shape == (150, 24, 3) and np.isfinite(motion.joints).all()
    assert load_bvh(files["bvh"]).num_frames == 150
    assert len(iio.imread(files["mp4"])) == 150
    assert _audio_streams(files["mp4"]) == 1  # the music is muxed in
    # scored beside the ground truth and the baselines, printed and in demo.json
    scores = summary["scores"]
    assert scores["held_out_windows"] == 1 and scores["training_windows"] == 6
    assert scores["ground_truth"]["mpjpe_m"] == 0.0 and scores["random_clip"]["plausibility_m"] < 1e-9
    assert all(np.isfinite(v) for column in ("dance", "mean_pose") for v in scores[column].values())
    assert set(summary["checks"]) and "pose plausibility" in proc.stdout
