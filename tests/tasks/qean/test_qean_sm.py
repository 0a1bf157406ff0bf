"""QEAN through the real ``sm`` entry point on tiny SYNTHETIC data written in the AIST++ layout.

``sm fit --recipe qean_mamba.yaml`` (one step, tiny SkeletonMamba backbone) -> a checkpoint ->
``sm predict`` from it writes the dance (.npz) and its video with the music (.mp4); ``sm test --recipe
qean.yaml`` prints our figures beside [QEAN] Table 1, labelled not comparable. The data are the toolkit's
beat-synchronised synthetic dances and drum tracks, saved as AIST++ motion pickles and ``<music id>.wav``;
the val / test lists sit in ``<root>/splits/`` as in the AIST++ annotations.
"""

from __future__ import annotations

import pickle
import re
import subprocess
import sys
from importlib.resources import files

import imageio_ffmpeg
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from skeleton_mamba.tasks.motion.io.safe_pickle import safe_load_pickle
from skeleton_mamba.tasks.motion.music.features import extract_music_features
from skeleton_mamba.tasks.motion.synthetic import synthesize_dance, synthesize_music, write_music
from skeleton_mamba.tasks.training.cli import main as sm_main
from skeleton_mamba.tasks.training.lightning_cli import run
from tests.helpers.retarget_rigs import HUMANOID, MIXAMO, build_rig, read_animated, rest_positions

TRAIN = ["gBR_sBM_cAll_d04_mBR0_ch01", "gPO_sBM_cAll_d10_mPO1_ch02"]
VAL = ["gBR_sBM_cAll_d05_mBR0_ch05"]
TEST = ["gPO_sBM_cAll_d11_mPO1_ch02", "gBR_sBM_cAll_d06_mBR0_ch02"]
SCALING = 93.0  # AIST++ stores smpl_trans in units of smpl_scaling
MODEL = {
    "network.hidden": 32, "network.heads": 2, "network.motion_layers": 1, "network.audio_layers": 1,
    "network.cross_layers": 1, "network.mlp_dim": 64, "network.num_periods": 2, "network.dropout": 0.0,
    "output_dir": "predictions",
}  # fmt: skip
LENGTHS = {"seed_frames": 12, "music_frames": 24, "predict_frames": 4, "generate_frames": 20}
# [QEAN] Table 1
QEAN_TABLE1 = {"FID_k": 30.1, "FID_g": 11.5, "Dist_k": 7.82, "Dist_g": 9.37, "BeatAlign": 0.239}


@pytest.fixture(scope="module")
def aistpp(tmp_path_factory):
    """``motions/*.pkl`` (60 fps, 1 s), ``music/mBR0.wav`` and ``mPO1.wav``, ``splits/crossmodal_*.txt``."""
    root = tmp_path_factory.mktemp("aistpp")
    for folder in ("motions", "music", "splits"):
        (root / folder).mkdir()
    for k, name in enumerate(TRAIN + VAL + TEST):
        motion = synthesize_dance(120.0, 1.0, fps=60.0, style=["bounce", "sway"][k % 2], seed=k)
        data = {
            "smpl_poses": motion.poses.reshape(-1, 72).astype(np.float32),
            "smpl_trans": (motion.root_position() * SCALING).astype(np.float32),
            "smpl_scaling": np.array([SCALING], dtype=np.float32),
        }
        with open(root / "motions" / f"{name}.pkl", "wb") as f:
            pickle.dump(data, f)
    for k, mid in enumerate(("mBR0", "mPO1")):
        wav = write_music(root / "music" / f"{mid}.wav", synthesize_music(100.0 + 20 * k, 1.0, seed=k))
        extract_music_features(wav, fps=60, cache_dir=root / "cache")  # cached once for every sm call
    for split, names in (("train", TRAIN), ("val", VAL), ("test", TEST)):
        (root / "splits" / f"crossmodal_{split}.txt").write_text("\n".join(names) + "\n")
    return root


def _overrides(root, backbone: bool) -> list[str]:
    args = [f"--model.init_args.{k}={v}" for k, v in MODEL.items()]
    args += [f"--data.init_args.{k}={v}" for k, v in LENGTHS.items()]  # linked to the model
    args += [
        "--trainer.accelerator=cpu", "--trainer.logger=false", "--trainer.callbacks=null",
        "--trainer.enable_progress_bar=false", f"--data.init_args.root={root}",
        f"--data.init_args.music_cache_dir={root / 'cache'}", "--data.init_args.batch_size=2",
        "--data.init_args.num_workers=0", "--data.init_args.synthetic=true",
    ]  # fmt: skip
    if backbone:
        tiny = files("skeleton_mamba.recipes") / "backbones" / "skeleton_mamba_tiny.yaml"
        args.append(f"--model.init_args.backbone={tiny}")
    return args


def _sm(args: list[str], cwd) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "skeleton_mamba.tasks", *args]
    proc = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    return proc


def test_sm_fit_qean_mamba_then_predict_from_the_checkpoint(aistpp, tmp_path):
    common = _overrides(aistpp, backbone=True)
    fit = _sm(
        ["fit", "--recipe", "qean_mamba.yaml", *common, "--trainer.max_steps=1", "--trainer.max_epochs=1",
         "--trainer.limit_train_batches=1", "--trainer.enable_checkpointing=true",
         f"--trainer.default_root_dir={tmp_path}"],
        tmp_path,
    )  # fmt: skip
    assert "`max_steps=1` reached" in fit.stdout + fit.stderr
    (ckpt,) = (tmp_path / "checkpoints").glob("*.ckpt")
    seed_file, music_file = aistpp / "motions" / f"{TEST[0]}.pkl", aistpp / "music" / "mPO1.wav"
    meaningless = {b: f"n{i}" for i, b in enumerate(HUMANOID)}
    rig = build_rig(tmp_path / "avatar.vrm", meaningless, rest_positions(), 5, vrm="1")
    _sm(
        ["predict", "--recipe", "qean_mamba.yaml", *common, f"--ckpt_path={ckpt}",
         f"--data.init_args.predict_seed={seed_file}", f"--data.init_args.predict_music={music_file}",
         f"--rig={rig}"],
        tmp_path,
    )  # fmt: skip
    stem = f"mPO1_{TEST[0]}"
    npz, mp4 = tmp_path / "predictions" / f"{stem}.npz", tmp_path / "predictions" / f"{stem}.mp4"
    # sm predict --rig: the dance on the VRM character too, its frame count and frame rate
    gltf, times, _, _ = read_animated(tmp_path / "predictions" / f"{stem}_rig.vrm")
    assert len(times) == len(np.load(npz)["joints"]) and gltf.animations[0].extras["fps"] == 60.0
    with np.load(npz, allow_pickle=False) as saved:
        frames = len(saved["joints"])  # the whole 1 s song danced (generate_frames is the test's length)
        assert abs(frames - 60) <= 1 and saved["smpl_poses"].shape == (frames, 72)
        assert float(saved["fps"]) == 60.0 and str(saved["skeleton"]) == "smpl24"
        poses, trans, scaling = saved["smpl_poses"], saved["smpl_trans"], saved["smpl_scaling"]
        root_position = trans / scaling
    raw = safe_load_pickle(seed_file)
    # the first 12 frames are the seed motion: same rotations (scipy), same root position in metres
    got = Rotation.from_rotvec(poses[:12].reshape(-1, 3).astype(np.float64)).as_matrix()
    want = Rotation.from_rotvec(raw["smpl_poses"][:12].reshape(-1, 3).astype(np.float64)).as_matrix()
    np.testing.assert_allclose(got, want, atol=1e-4)
    np.testing.assert_allclose(root_position[:12], raw["smpl_trans"][:12] / SCALING, atol=1e-5)
    assert np.isfinite(poses).all()
    probe = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-i", str(mp4)], capture_output=True, text=True)
    assert re.search(r"Stream .*Video:", probe.stderr), probe.stderr[-2000:]
    assert re.search(r"Stream .*Audio:", probe.stderr), probe.stderr[-2000:]  # the music is muxed


def test_sm_test_prints_our_figures_beside_the_paper_table(aistpp, tmp_path, monkeypatch, caplog):
    monkeypatch.chdir(tmp_path)
    caplog.set_level("INFO")
    assert run(["test", "--recipe", "qean.yaml", *_overrides(aistpp, backbone=False)]) == 0
    text = caplog.text
    # default test_split [val, test]: the val list of <root>/splits plus the test list = 3 sequences
    header = "protocol fact: 3 generated sequences x 20 frames (paper: 40 x 1200); real set: 5 sequences"
    assert header in text
    assert "NOT COMPARABLE with [QEAN] Table 1: synthetic data in the AIST++ layout" in text
    for name, paper in QEAN_TABLE1.items():
        match = re.search(rf"^{name}\s+(\S+)\s+(\S+)\s+(\S+)$", text, re.MULTILINE)
        assert match, f"{name} row missing:\n{text[-2000:]}"
        ours, paper_value = float(match.group(1)), float(match.group(2))
        assert np.isfinite(ours) and paper_value == paper
    assert 0.0 <= float(re.search(r"^BeatAlign\s+(\S+)", text, re.MULTILINE).group(1)) <= 1.0


def test_sm_predict_refuses_a_bad_rig_before_the_model_and_data(aistpp, tmp_path, capsys):
    """``sm predict --rig`` of a rig lacking the feet, or a missing file: one line, exit 2, nothing read or
    written (the checkpoint named does not even exist)."""
    footless = {b: p for b, p in rest_positions().items() if "Foot" not in b and "Toes" not in b}
    rig = build_rig(tmp_path / "footless.glb", MIXAMO, footless)
    argv = ["predict", "--recipe", "qean_mamba.yaml", *_overrides(aistpp, backbone=False),
            f"--ckpt_path={tmp_path / 'never.ckpt'}"]  # fmt: skip
    for extra, expected in (
        ([f"--rig={rig}"], "footless.glb: the rig lacks the humanoid bones leftFoot"),
        ([f"--rig={tmp_path / 'nosuch.vrm'}"], "nosuch.vrm: no such file"),
        ([f"--map={tmp_path / 'map.yaml'}"], "--map"),
    ):
        assert sm_main([*argv, *extra]) == 2
        err = capsys.readouterr().err
        assert expected in err and err.strip().count("\n") == 0, err
    assert not (tmp_path / "predictions").exists()
