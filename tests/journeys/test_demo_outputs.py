"""Journey (c): what ``sm dance``, ``sm generate``, ``sm stream`` and ``sm predict`` write, as
``docs/reference/cli.md`` names it, is listed on the console, and every motion file among it is read back by
``sm view``, ``sm render`` and ``sm export`` (the files a user would open next). Tiny random models; the
EgoDance ``sm predict`` journey trains a one-step demo model first and is marked slow."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints
from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music
from skeleton_mamba.tasks.stream.module import StreamDanceModule
from skeleton_mamba.tasks.text2motion.module import TextToMotionModule
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.checkpoint_files import save_module_checkpoint
from tests.helpers.gltf_reader import glb_joint_positions
from tests.helpers.retarget_rigs import MIXAMO, build_rig, read_animated, rest_positions

MIXER = {"d_state": 8, "headdim": 8, "chunk_size": 16}
TINY = {"dim": 16, "depth": 1, "heads": 2, "mlp_dim": 32, "mixer": MIXER}
LISTED = re.compile(r"^\s+\w+\s+(\S+)$")  # "  npz  path" lines of the commands' file lists


def _listed(printed: str) -> list[Path]:
    return [Path(m.group(1)) for line in printed.splitlines() if (m := LISTED.match(line))]


def _readable_by_every_command(paths: list[Path], tmp_path: Path) -> None:
    """``sm view`` (all motions in one page), ``sm render`` and ``sm export`` of each motion file."""
    motions = [p for p in paths if p.suffix in (".npz", ".bvh", ".glb", ".npy")]
    assert motions
    assert sm_main(["view", *map(str, motions), "--out", str(tmp_path / "view.html")]) == 0
    for i, path in enumerate(motions):
        glb = tmp_path / f"{i}_{path.stem}.glb"
        assert sm_main(["export", str(path), "--out", str(glb)]) == 0
        np.testing.assert_allclose(glb_joint_positions(glb)[1], load_joints(path).joints, atol=2e-4, rtol=0)
    first = motions[0]
    assert sm_main(["render", str(first), "--out", str(tmp_path / "first.gif"), "--quiet"]) == 0


@pytest.fixture(scope="module")
def song(tmp_path_factory) -> Path:
    return write_music(tmp_path_factory.mktemp("song") / "song.wav", synthesize_music(120.0, 3.0, seed=1))


def test_sm_dance_files_are_listed_and_readable(tmp_path, song, tiny_egodance_module, capsys):
    import imageio.v3 as iio

    torch.manual_seed(0)
    ckpt = save_module_checkpoint(tiny_egodance_module(), tmp_path / "emm.ckpt")
    video = (np.random.default_rng(0).random((90, 32, 32, 3)) * 255).astype(np.uint8)
    iio.imwrite(tmp_path / "ego.mp4", video, fps=30)
    args = ["dance", "--ckpt", str(ckpt), "--music", str(song), "--video", str(tmp_path / "ego.mp4")]
    assert sm_main([*args, "--out", str(tmp_path / "out"), "--steps", "1", "--render-size", "160x128"]) == 0
    listed = _listed(capsys.readouterr().out)
    # docs/reference/cli.md: DIR/dance.{npz,bvh,mp4} (+ the .glb and the music slice)
    assert sorted(p.name for p in listed) == ["dance.bvh", "dance.glb", "dance.mp4", "dance.npz", "dance.wav"]
    assert all(p.stat().st_size > 0 for p in listed)
    assert load_motion(tmp_path / "out" / "dance.npz").num_frames == 90
    _readable_by_every_command(listed, tmp_path)


def test_sm_generate_files_are_listed_and_readable(tmp_path, capsys):
    torch.manual_seed(0)
    backbone = SkeletonMambaConfig(**{**TINY, "mixer": MixerConfig(**MIXER)})
    module = TextToMotionModule(backbone=backbone, diffusion_steps=10, sampling_steps=2)
    ckpt = save_module_checkpoint(module, tmp_path / "t2m.ckpt")
    args = ["generate", "--checkpoint", str(ckpt), "--text", "a person waves", "--length", "20"]
    assert sm_main([*args, "--out", str(tmp_path / "gen"), "--render", "gif"]) == 0
    listed = _listed(capsys.readouterr().out)
    names = sorted(p.name for p in listed)
    assert names == sorted(f"000_a_person_waves{s}" for s in (".npy", "_features.npy", ".glb", ".gif"))
    assert all(p.is_file() for p in listed)
    _readable_by_every_command([p for p in listed if p.suffix != ".gif"], tmp_path)


def test_sm_stream_files_are_listed_and_readable(tmp_path, song, capsys):
    torch.manual_seed(0)
    ckpt = save_module_checkpoint(StreamDanceModule(backbone={**TINY, "causal": True}), tmp_path / "s.ckpt")
    args = ["stream", "--ckpt", str(ckpt), "--music", str(song), "--out", str(tmp_path / "live")]
    assert sm_main([*args, "--render-size", "160x128", "--threads", "1"]) == 0
    listed = _listed(capsys.readouterr().out)
    # docs/reference/cli.md: DIR/<name>.{npz,bvh,mp4} (+ the .glb and the music slice)
    assert sorted(p.name for p in listed) == ["song.bvh", "song.glb", "song.mp4", "song.npz", "song.wav"]
    assert (tmp_path / "live" / "song_stream.json").is_file()
    _readable_by_every_command(listed, tmp_path)


@pytest.mark.slow
def test_sm_predict_of_the_egodance_demo_writes_and_lists_the_dances(tmp_path):
    """``sm fit`` of the demo recipe on a small generated set (1 step), then ``sm predict`` with it."""
    data = ["--data.init_args.count=9", "--data.init_args.duration_s=5.0", "--data.init_args.frame_size=16",
            "--data.init_args.image_size=16", "--data.init_args.num_rooms=1"]  # fmt: skip

    def sm(*args: str) -> str:
        proc = subprocess.run([sys.executable, "-m", "skeleton_mamba.tasks", *args, *data], cwd=tmp_path,
                              capture_output=True, text=True, timeout=900)  # fmt: skip
        assert proc.returncode == 0, proc.stderr[-3000:]
        return proc.stdout + proc.stderr

    sm(
        "fit",
        "--recipe",
        "egodance_demo.yaml",
        "--trainer.max_steps=1",
        "--trainer.enable_progress_bar=false",
    )
    ckpt = tmp_path / "runs/egodance_demo/version_0/checkpoints/last.ckpt"
    rig = build_rig(tmp_path / "hero.glb", MIXAMO, rest_positions(a_pose=True), roll_seed=2)
    printed = sm("predict", "--recipe", "egodance_demo.yaml", f"--ckpt_path={ckpt}",
                 "--trainer.enable_progress_bar=false", f"--rig={rig}")  # fmt: skip
    folder = tmp_path / "runs/egodance_demo/version_1/predictions"
    dances = sorted(folder.glob("*_dance.npz"))
    where = folder.relative_to(tmp_path)  # as the run's log dir is given: relative to the working folder
    assert len(dances) == 2 and f"2 dances written to {where}" in printed  # the 2 test windows
    for npz in dances:
        for suffix in (".npz", ".bvh", ".glb", ".mp4", ".wav"):
            path = npz.with_suffix(suffix)
            assert path.stat().st_size > 0 and str(path.relative_to(tmp_path)) in printed
        on_rig = npz.with_name(f"{npz.stem}_rig.glb")  # sm predict --rig: the dance on the character
        assert str(on_rig.relative_to(tmp_path)) in printed
        assert len(read_animated(on_rig)[1]) == len(np.load(npz)["joints"])
    _readable_by_every_command([dances[0], dances[0].with_suffix(".glb")], tmp_path)
