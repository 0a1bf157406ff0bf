"""``sm dance``: a 12 s track as 4 overlapping windows -> npz + BVH + mp4 with music, continuous at seams."""

import subprocess

import numpy as np
import pytest
import torch
from checkpoint_files import save_module_checkpoint

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.egodance.model import EMM

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

    from skeleton_mamba.tasks.motion.bvh import load_bvh
    from skeleton_mamba.tasks.motion.motion_file import load_motion

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
    assert "dance.mp4" in capsys.readouterr().out


def test_sm_dance_says_when_the_video_is_shorter_than_the_music(inputs, capsys):
    import imageio.v3 as iio

    from skeleton_mamba.tasks.egodance.dance_cli import main
    from skeleton_mamba.tasks.motion.motion_file import load_motion

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


def test_sm_dance_root_is_continuous_across_window_seams(inputs, monkeypatch):
    from skeleton_mamba.tasks.motion.motion_file import load_motion

    tmp, ckpt, wav = inputs
    monkeypatch.setattr(EMM, "forward", _walking_forward)
    # 360 frames: 4 windows of 150 / 75; no head guidance, which would move the oracle's walk
    assert _dance(tmp, ckpt, wav, tmp / "walk.npz", "--no-render", "--head", "none") == 0
    root = load_motion(tmp / "walk.npz").root_position()
    steps = np.linalg.norm(np.diff(root[:, [0, 2]], axis=0), axis=1)
    normal = np.hypot(STEP_X, STEP_Z)
    # every frame-to-frame step, the seams at frames 75, 150, 225 (window starts) included, is the walk's
    np.testing.assert_allclose(steps, normal, rtol=1e-3)
    np.testing.assert_allclose(root[:, 0], STEP_X * np.arange(360), atol=1e-4)
    np.testing.assert_allclose(root[:, 1], 0.9, atol=1e-5)


def test_sm_dance_refuses_long_tracks_for_heading_canonical_checkpoints(inputs):
    from skeleton_mamba.tasks.motion.errors import InputError

    tmp, ckpt, wav = inputs
    checkpoint = torch.load(ckpt, weights_only=True)
    checkpoint["datamodule_hyper_parameters"] = {"canonicalize_init_head": True}
    canonical = tmp / "canonical.ckpt"
    torch.save(checkpoint, canonical)
    # 360 frames would be stitched from windows in the world-yaw frame: a clear error instead
    with pytest.raises(InputError, match="canonicalize_init_head.*at most 150 frames"):
        _dance(tmp, canonical, wav, tmp / "canonical_out", "--no-render")


def test_a_checkpoint_loads_without_the_random_resnet_warning(inputs, tiny_egodance_module):
    """Built alone, the tiny module warns that its ResNet is random; loaded from a checkpoint, whose weights
    replace it, it does not."""
    import warnings

    from skeleton_mamba.tasks.egodance.module import EgoDanceModule
    from skeleton_mamba.tasks.motion.errors import RandomWeightsWarning
    from skeleton_mamba.tasks.training.checkpoints import load_module_and_checkpoint

    with pytest.warns(RandomWeightsWarning, match="randomly initialised"):
        tiny_egodance_module()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        module, _ = load_module_and_checkpoint(EgoDanceModule, inputs[1])
    assert isinstance(module, EgoDanceModule)
    random_weights = [str(w.message) for w in caught if issubclass(w.category, RandomWeightsWarning)]
    assert not random_weights
