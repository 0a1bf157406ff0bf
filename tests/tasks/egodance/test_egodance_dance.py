"""``sm dance``: a 12 s track as 4 overlapping windows -> npz + BVH + mp4 with music, continuous at seams."""

import re
import subprocess

import numpy as np
import pytest
import torch

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.egodance.model import EMM
from tests.helpers.checkpoint_files import save_module_checkpoint

IDENTITY_6D = torch.tensor([1.0, 0.0, 0.0, 0.0, 1.0, 0.0])
STEP_X, STEP_Z = 0.01, 0.004  # metres per frame of the oracle's walk


def _walking_forward(self, x_t, t, context=None, mask=None):
    """Oracle EMM: what a model trained on per-window canonical data predicts, whatever x_t is: the rest
    pose walking in a straight line that starts at x = z = 0 in the window's first frame, pelvis 0.9 m up."""
    out = torch.zeros_like(x_t)
    out[..., :6] = IDENTITY_6D.to(x_t.dtype)
    k = torch.arange(x_t.shape[1], dtype=x_t.dtype)
    out[:, :, 0, 6] = STEP_X * k
    out[:, :, 0, 7] = 0.9
    out[:, :, 0, 8] = STEP_Z * k
    return out


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, tiny_egodance_module):
    """A tiny EMM checkpoint, a 12 s synthetic track and a 12 s egocentric video."""
    import imageio.v3 as iio

    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

    tmp = tmp_path_factory.mktemp("dance")
    torch.manual_seed(0)
    module = tiny_egodance_module()
    ckpt = tmp / "emm.ckpt"
    save_module_checkpoint(module, ckpt)
    wav = write_music(tmp / "song.wav", synthesize_music(120.0, 12.0))
    video = (np.random.default_rng(0).random((360, 32, 32, 3)) * 255).astype(np.uint8)
    iio.imwrite(tmp / "ego.mp4", video, fps=30)
    return tmp, ckpt, wav


def _dance(tmp, ckpt, wav, out, *extra):
    from skeleton_mamba.tasks.egodance.dance_cli import main

    args = ["--ckpt", str(ckpt), "--music", str(wav), "--video", str(tmp / "ego.mp4"), "--out", str(out)]
    return main(args + ["--steps", "2", "--render-size", "160x128", *extra])


def _audio_streams(path) -> int:
    import imageio_ffmpeg

    probe = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True, text=True
    )
    return sum(" Audio: " in line for line in probe.stderr.splitlines())


def test_sm_dance_writes_npz_bvh_and_mp4_with_music(inputs, capsys):
    import imageio.v3 as iio

    from skeleton_mamba.tasks.motion.formats.bvh import load_bvh
    from skeleton_mamba.tasks.motion.formats.motion_file import load_motion

    tmp, ckpt, wav = inputs
    assert _dance(tmp, ckpt, wav, tmp / "out") == 0
    motion = load_motion(tmp / "out/dance.npz")
    assert motion.poses.shape == (360, 24, 3) and np.isfinite(motion.joints).all()
    bvh = load_bvh(tmp / "out/dance.bvh")
    assert bvh.num_frames == 360 and abs(bvh.fps - 30.0) < 1e-6
    order = [bvh.names.index(name) for name in SMPL24.joint_names]  # BVH files list joints depth-first
    np.testing.assert_allclose(bvh.joint_positions()[:, order], motion.joints, atol=1e-3)  # BVH FK = ours
    assert len(iio.imread(tmp / "out/dance.mp4")) == 360
    assert _audio_streams(tmp / "out/dance.mp4") == 1
    out = capsys.readouterr().out
    assert "dance.mp4" in out
    stages = re.search(r"seconds per stage: (.*)", out).group(1)  # every stage timed, in the order run
    assert [part.rsplit(" ", 1)[0] for part in stages.split(", ")] == [
        "music features", "video", "sampling", "writing"
    ]  # fmt: skip
    assert all(float(part.rsplit(" ", 1)[1]) >= 0 for part in stages.split(", "))


def test_sm_dance_says_when_the_video_is_shorter_than_the_music(inputs, capsys):
    import imageio.v3 as iio

    from skeleton_mamba.tasks.egodance.dance_cli import main
    from skeleton_mamba.tasks.motion.formats.motion_file import load_motion

    tmp, ckpt, wav = inputs  # a 12 s track
    short = (np.random.default_rng(1).random((150, 32, 32, 3)) * 255).astype(np.uint8)
    iio.imwrite(tmp / "short.mp4", short, fps=30)  # 5 s
    args = ["--ckpt", str(ckpt), "--music", str(wav), "--video", str(tmp / "short.mp4")]
    args += ["--out", str(tmp / "short.npz"), "--steps", "2", "--no-render", "--head", "none"]
    assert main(args) == 0
    assert load_motion(tmp / "short.npz").poses.shape[0] == 150
    err = capsys.readouterr().err
    assert "warning: the video has 150 frames (5.0 s at 30 fps), the music 361 (12.0 s)" in err
    assert "the dance covers the first 5.0 s" in err


@pytest.mark.parametrize("sampler", ["ddim", "dpmpp", "unipc"])
def test_sm_dance_root_is_continuous_across_window_seams(inputs, monkeypatch, sampler):
    """Long-form stitching (in-painted overlaps) through every sampler that takes steps."""
    from skeleton_mamba.tasks.motion.formats.motion_file import load_motion

    tmp, ckpt, wav = inputs
    monkeypatch.setattr(EMM, "forward", _walking_forward)
    # 360 frames: 4 windows of 150 / 75; no head guidance, which would move the oracle's walk
    out = tmp / f"walk_{sampler}.npz"
    assert _dance(tmp, ckpt, wav, out, "--no-render", "--head", "none", "--sampler", sampler) == 0
    root = load_motion(out).root_position()
    steps = np.linalg.norm(np.diff(root[:, [0, 2]], axis=0), axis=1)
    normal = np.hypot(STEP_X, STEP_Z)
    # every frame-to-frame step, the seams at frames 75, 150, 225 (window starts) included, is the walk's
    np.testing.assert_allclose(steps, normal, rtol=1e-3)
    np.testing.assert_allclose(root[:, 0], STEP_X * np.arange(360), atol=1e-4)
    np.testing.assert_allclose(root[:, 1], 0.9, atol=1e-5)


TURN = 0.01  # radians per frame of the turning oracle
STEP = 0.012  # metres per frame along its heading


def _turning_forward(self, x_t, t, context=None, mask=None):
    """Oracle EMM of a model trained on windows turned to face their first heading: whatever x_t is, the
    rest pose walking forward (along its heading) while turning TURN per frame, starting at x = z = 0 and
    facing +z at the window's first frame (the rest pose's head faces where its pelvis does)."""
    out = torch.zeros_like(x_t)
    k = torch.arange(x_t.shape[1], dtype=torch.float64)
    yaw = TURN * k
    c, s = torch.cos(yaw), torch.sin(yaw)
    out[..., :6] = IDENTITY_6D.to(x_t.dtype)
    # the root's orientation: a turn about +y by yaw (first two columns (c, 0, -s) and (0, 1, 0))
    out[:, :, 0, 0], out[:, :, 0, 2] = c.to(x_t.dtype), (-s).to(x_t.dtype)
    position = torch.cumsum(torch.stack([s, c], -1) * STEP, 0) - torch.stack([s, c], -1)[:1] * STEP
    out[:, :, 0, 6] = position[:, 0].to(x_t.dtype)
    out[:, :, 0, 7] = 0.9
    out[:, :, 0, 8] = position[:, 1].to(x_t.dtype)
    return out


def test_sm_dance_joins_heading_canonical_windows_into_one_turning_walk(inputs, monkeypatch, capsys):
    """A checkpoint trained with canonicalize_init_head dances a 12 s track (4 windows): each window is
    sampled facing its first heading, found from the previous window's dance, and the windows joined give
    the one walk on a circle the oracle describes: heading TURN * t, position sum of the steps along it."""
    from skeleton_mamba.tasks.motion.formats.motion_file import load_motion

    tmp, ckpt, wav = inputs
    checkpoint = torch.load(ckpt, weights_only=True)
    checkpoint["hyper_parameters"]["canonicalize_init_head"] = True  # linked from the data module in sm fit
    canonical = tmp / "canonical.ckpt"
    torch.save(checkpoint, canonical)
    monkeypatch.setattr(EMM, "forward", _turning_forward)
    args = ("--no-render", "--head", "none", "--heading", "none")  # the frames from the motion, not the video
    assert _dance(tmp, canonical, wav, tmp / "turn.npz", *args) == 0
    assert (
        "4 windows of 150 frames every 75, each facing its first frame's head heading, held by the sampled "
        "motion" in capsys.readouterr().out
    )
    motion = load_motion(tmp / "turn.npz")
    yaw = np.arange(360) * TURN
    steps = np.stack([np.sin(yaw), np.cos(yaw)], -1) * STEP
    expected = np.cumsum(steps, 0) - steps[:1]  # x, z
    root = motion.root_position()
    np.testing.assert_allclose(root[:, [0, 2]], expected, atol=1e-4)  # 3.6 radians of turn, 4.3 m walked
    np.testing.assert_allclose(root[:, 1], 0.9, atol=1e-5)
    orient = motion.poses[:, 0]  # axis-angle of the root: about +y by the heading
    np.testing.assert_allclose(orient[:, [0, 2]], 0.0, atol=1e-4)
    np.testing.assert_allclose(np.unwrap(orient[:, 1]), yaw, atol=1e-4)
    # a checkpoint from before the module had the setting: its data module's says it
    del checkpoint["hyper_parameters"]["canonicalize_init_head"]
    checkpoint["datamodule_hyper_parameters"] = {"canonicalize_init_head": True}
    torch.save(checkpoint, tmp / "older.ckpt")
    assert _dance(tmp, tmp / "older.ckpt", wav, tmp / "older.npz", "--no-render", "--head", "none") == 0
    np.testing.assert_allclose(load_motion(tmp / "older.npz").root_position(), root, atol=1e-6)
    # a world-yaw checkpoint (translation-only stitching) cannot join them: it turns back at every seam
    assert _dance(tmp, ckpt, wav, tmp / "plain.npz", "--no-render", "--head", "none") == 0
    plain = load_motion(tmp / "plain.npz").root_position()
    assert np.abs(plain[:, [0, 2]] - expected).max() > 1.0


def test_a_checkpoint_loads_without_the_random_resnet_warning(inputs, tiny_egodance_module):
    """Built alone, the tiny module warns that its ResNet is random; loaded from a checkpoint, whose weights
    replace it, it does not."""
    import warnings

    from skeleton_mamba.errors import RandomWeightsWarning
    from skeleton_mamba.tasks.egodance.module import EgoDanceModule
    from skeleton_mamba.tasks.training.checkpoints import load_module_and_checkpoint

    with pytest.warns(RandomWeightsWarning, match="randomly initialised"):
        tiny_egodance_module()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        module, _ = load_module_and_checkpoint(EgoDanceModule, inputs[1])
    assert isinstance(module, EgoDanceModule)
    random_weights = [str(w.message) for w in caught if issubclass(w.category, RandomWeightsWarning)]
    assert not random_weights


def test_a_model_of_the_head_turns_refuses_to_dance_without_them(inputs, tiny_egodance_module, tmp_path):
    """An EMM conditioned on the head's turns (``heading_condition``) is refused ``--heading none`` in one
    line,
    and a video whose frames show no turning scene (the fixture's noise) in one line naming the video."""
    from skeleton_mamba.errors import InputError

    tmp, _, wav = inputs
    ckpt = tmp_path / "turns.ckpt"
    save_module_checkpoint(tiny_egodance_module(heading_condition=True), ckpt)
    with pytest.raises(
        InputError, match="dances to the head's turns read from the video: drop --heading none"
    ):
        _dance(tmp, ckpt, wav, tmp_path / "a", "--no-render", "--heading", "none")
    with pytest.raises(InputError, match=r"ego\.mp4: the head's turns could not be read from this video"):
        _dance(tmp, ckpt, wav, tmp_path / "b", "--no-render")
