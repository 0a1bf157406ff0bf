"""``sm dance --video`` from per-frame features decoded as a stream (issue 33): the same dance as from all
the frames held at once, in memory that does not grow with the video's length."""

import dataclasses
import subprocess
import sys
import textwrap

import imageio_ffmpeg
import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.egodance import dance_cli
from skeleton_mamba.tasks.egodance.frames import read_video_frames
from skeleton_mamba.tasks.egodance.head_estimator import (
    HeadEstimatorConfig,
    HeadFeatureStream,
    HeadTrajectoryEstimator,
    estimate_long_trajectory,
    long_window_starts,
)
from skeleton_mamba.tasks.egodance.representation import motion_joints
from skeleton_mamba.tasks.egodance.sampling import sample_long_dance
from skeleton_mamba.tasks.egodance.video_features import encode_video
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.music.features import extract_music_features
from tests.helpers.checkpoint_files import save_module_checkpoint
from tests.helpers.peak_memory import PEAK_KIB_SOURCE


def _old_estimate_long_trajectory(estimator, frames, window):
    """estimate_long_trajectory before features (verbatim): the estimator on windows of the held frames."""
    total = frames.shape[0]
    if total <= window:
        positions, rotations = estimator(frames[None])
        return positions[0], rotations[0]
    positions = frames.new_zeros(total, 3)
    rotations = frames.new_zeros(total, 3, 3)
    start = 0
    while True:
        start = min(start, total - window)
        pos, rot = estimator(frames[None, start : start + window])
        pos, rot = pos[0], rot[0]
        if start > 0:
            pos[:, [0, 2]] += positions[start, [0, 2]] - pos[0, [0, 2]]
        positions[start : start + window] = pos
        rotations[start : start + window] = rot
        if start + window >= total:
            return positions, rotations
        start += window - 1


def _video(path, num_frames: int, width: int, height: int, seed: int = 0):
    """A random 8-pixel-block texture drifting a pixel a frame (ego-motion for the head estimator)."""
    rng = np.random.default_rng(seed)
    blocks = rng.integers(0, 256, (-(-height // 8), (width + num_frames) // 8 + 1, 3), dtype=np.uint8)
    texture = np.repeat(np.repeat(blocks, 8, axis=0), 8, axis=1)[:height]
    writer = imageio_ffmpeg.write_frames(str(path), (width, height), fps=30, macro_block_size=16)
    writer.send(None)
    for t in range(num_frames):
        writer.send(np.ascontiguousarray(texture[:, t : t + width]))
    writer.close()
    return path


def test_long_window_starts_by_hand():
    assert long_window_starts(8, 10) == [0]
    assert long_window_starts(10, 10) == [0]
    assert long_window_starts(11, 10) == [0, 1]
    assert long_window_starts(37, 10) == [0, 9, 18, 27]  # 27 + 10 = 37: the last one ends at the end
    assert long_window_starts(30, 10) == [0, 9, 18, 20]  # the last one moved back to end at frame 29
    with pytest.raises(ValueError, match="at least 2"):
        long_window_starts(5, 1)


@pytest.mark.parametrize("total", [8, 10, 30, 37, 49])
@pytest.mark.parametrize("chunk", [1, 7, 16])
def test_streamed_head_features_give_the_trajectory_of_the_held_frames(total, chunk):
    torch.manual_seed(0)
    estimator = HeadTrajectoryEstimator(HeadEstimatorConfig(input_size=16, channels=(8, 8), dim=8, layers=1))
    estimator.eval()
    frames = torch.rand(total, 3, 24, 24)
    stream = HeadFeatureStream(estimator, window=10)
    for i in range(0, total, chunk):
        stream.push(frames[i : i + chunk])
    features = stream.finish()
    assert len(features) == total and sorted(features.window_first) == long_window_starts(total, 10)[1:]
    got = estimate_long_trajectory(estimator, features, window=10)
    expected = _old_estimate_long_trajectory(estimator, frames, window=10)
    for a, b in zip(got, expected, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)
    raw = estimate_long_trajectory(estimator, frames, window=10)  # the frames API is kept
    torch.testing.assert_close(raw[0], expected[0], rtol=0, atol=0)
    with pytest.raises(ValueError, match="windows of 10 frames, not 12"):
        estimate_long_trajectory(estimator, features, window=12)


@pytest.fixture(scope="module")
def dance_inputs(tmp_path_factory, tiny_egodance_module):
    """A tiny EMM checkpoint (vision + head estimator), a 100-frame 48x40 video and a 3.4 s song."""
    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

    tmp = tmp_path_factory.mktemp("video_dance")
    torch.manual_seed(0)
    module = tiny_egodance_module().eval()
    ckpt = tmp / "emm.ckpt"
    save_module_checkpoint(module, ckpt)
    wav = write_music(tmp / "song.wav", synthesize_music(120.0, 3.4))
    video = _video(tmp / "ego.mp4", 100, 48, 40)
    return tmp, module, ckpt, wav, video


def test_sm_dance_from_streamed_features_equals_the_all_frames_dance(dance_inputs, capsys):
    """The CLI's dance (features) against the dance of all the frames held, as ``sm dance`` did it: frames
    read at the model's size, the verbatim old head estimate, sampling on windows of frames; same seed."""
    tmp, module, ckpt, wav, video = dance_inputs
    argv = ["--ckpt", str(ckpt), "--music", str(wav), "--video", str(video), "--steps", "2", "--seed", "3"]
    argv += ["--window", "40", "--overlap", "20", "--head-weight", "0.5", "--no-render"]
    assert dance_cli.main([*argv, "--out", str(tmp / "new.npz")]) == 0
    assert "head trajectory estimated from the video" in capsys.readouterr().out

    music = torch.from_numpy(extract_music_features(wav, fps=30).features.astype(np.float32))
    frames = read_video_frames(video, module.hparams.image_size, max_frames=len(music) + 2)
    n = min(len(frames), len(music))
    assert n == 100
    music, frames = music[:n], frames[:n]
    head = _old_estimate_long_trajectory(module.head_estimator, frames, 40)[0]
    old = sample_long_dance(
        module.ema.module, module.diffusion, music, frames, head, window=40, overlap=20,
        **dataclasses.asdict(module.sampling.override(sampling_steps=2)),
        head_guidance_weight=0.5, head_guidance_steps=module.head_guidance.steps,
        generator=torch.Generator().manual_seed(3),
    )  # fmt: skip
    got = load_motion(tmp / "new.npz").joints
    np.testing.assert_allclose(got, motion_joints(old.float()).numpy(), rtol=1e-4, atol=1e-5)


def test_video_features_are_those_of_the_held_frames(dance_inputs):
    """z_v (T, Dc) and the dance tokens from features equal the frames path's (EMA and raw weights)."""
    tmp, module, ckpt, wav, video = dance_inputs
    size = module.hparams.image_size
    frames = read_video_frames(video, size)
    for model in (module.ema.module, module.model):
        features = encode_video(video, size, model.vision_encoder, module.head_estimator, window=40, chunk=7)
        assert features.num_frames == 100 and features.vision.shape == (100, model.context_dim)
        with torch.no_grad():
            held = model.vision_encoder(frames[None])[0]
        torch.testing.assert_close(features.vision, held, rtol=1e-5, atol=1e-6)
        music = torch.randn(100, model.config.music_dim)
        kwargs = dict(window=40, overlap=20, sampling_steps=2, head_guidance_weight=0.0)
        old = sample_long_dance(
            model, module.diffusion, music, frames, generator=torch.Generator().manual_seed(1), **kwargs
        )
        new = sample_long_dance(
            model, module.diffusion, music, vision=features.vision,
            generator=torch.Generator().manual_seed(1), **kwargs,
        )  # fmt: skip
        torch.testing.assert_close(new, old, rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="not both"):
        sample_long_dance(model, module.diffusion, music, frames, vision=features.vision, **kwargs)
    with pytest.raises(ValueError, match="eval mode"):
        encode_video(video, size, module.model.vision_encoder.train())
    module.eval()


_PEAK_RSS = PEAK_KIB_SOURCE + textwrap.dedent(
    """
    import sys, warnings
    import torch
    from transformers import ResNetConfig
    from skeleton_mamba.tasks.egodance.encoders import VisionEncoder
    from skeleton_mamba.tasks.egodance.head_estimator import HeadEstimatorConfig, HeadTrajectoryEstimator
    from skeleton_mamba.tasks.egodance.video_features import encode_video
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    torch.manual_seed(0)
    layers = ResNetConfig(embedding_size=8, hidden_sizes=[8, 16], depths=[1, 1], layer_type="basic")
    vision = VisionEncoder(16, resnet_config=layers, image_size=int(sys.argv[2])).eval()
    head = HeadTrajectoryEstimator(HeadEstimatorConfig(input_size=16, channels=(8, 8), dim=8, layers=1))
    head.eval()
    encode_video(sys.argv[1], int(sys.argv[2]), vision, head, window=150, max_frames=48)  # warm up
    before = peak_kib()
    features = encode_video(sys.argv[1], int(sys.argv[2]), vision, head, window=150)
    print(features.num_frames, peak_kib() - before)
    """
)


@pytest.mark.slow  # about 40 s: two interpreters, 990 frames of 640x480 written and decoded
def test_video_feature_memory_does_not_grow_with_the_length(tmp_path):
    """Peak RSS growth (KiB, fresh interpreter, after a warm-up pass) of encoding 3 s and 30 s of 640x480
    video at a 112 px model size: holding the frames as the old path did would add 810 * 3 * 112^2 * 4 B
    = 122 MB for the 27 s more; the features add 810 * (16 + 8) floats = 78 KB."""
    peaks = {}
    for frames in (90, 900):
        path = _video(tmp_path / f"v{frames}.mp4", frames, 640, 480)
        proc = subprocess.run([sys.executable, "-c", _PEAK_RSS, str(path), "112"], capture_output=True,
                              text=True, timeout=600, check=True)  # fmt: skip
        count, peak_kib = (int(v) for v in proc.stdout.split())
        assert count == frames
        peaks[frames] = peak_kib
    held_kib = (900 - 90) * 3 * 112 * 112 * 4 // 1024
    assert peaks[900] - peaks[90] < 8 * 1024 < held_kib // 10, peaks  # under a tenth of the frames held


def test_encode_condition_refuses_vision_features_that_do_not_fit(tiny_egodance_module):
    model = tiny_egodance_module().model.eval()
    music, frames = torch.randn(1, 6, 35), torch.rand(1, 6, 3, 32, 32)
    vision = model.vision_encoder(frames)
    from_features = model.encode_condition(music, vision=vision)
    torch.testing.assert_close(from_features, model.encode_condition(music, frames))
    with pytest.raises(ValueError, match="give frames or their vision features, not both"):
        model.encode_condition(music, frames, vision)
    misfit = r"vision features \(1, 5, 16\) do not fit music \(1, 6\) and Dc = 16"
    with pytest.raises(ValueError, match=misfit):
        model.encode_condition(music, vision=vision[:, :5])
    network = {**tiny_egodance_module().hparams["network"], "use_vision": False}
    music_only = tiny_egodance_module(network=network, use_head_estimator=False, head_source="none").model
    with pytest.raises(ValueError, match=r"music-only \(use_vision=False\) but vision features were given"):
        music_only.encode_condition(music, vision=vision)


_PEAK_8K = PEAK_KIB_SOURCE + textwrap.dedent(
    """
    import sys
    from skeleton_mamba.tasks.egodance.frames import iter_video_frames
    chunks = [len(chunk) for chunk in iter_video_frames(sys.argv[1], 112)]
    print(len(chunks), sum(chunks), peak_kib())
    """
)


def test_an_8k_video_is_decoded_one_frame_at_a_time(tmp_path):
    """A 7680x4320 video (33 megapixels a frame, inside the admitted size): each chunk holds one frame
    (:data:`CHUNK_PIXELS`), so the decoding process peaks near one frame's uint8 + float copies (0.5 GB)
    above the interpreter, not at all 12 frames' (measured here: 11.6 GB before, 0.84 GB after; 2 GB in a
    fresh CI environment)."""
    path = tmp_path / "8k.avi"
    ffmpeg = imageio_ffmpeg.get_ffmpeg_exe()
    source = ["-f", "lavfi", "-i", "testsrc=size=7680x4320:rate=30", "-frames:v", "12"]
    encode = ["-c:v", "mjpeg", "-q:v", "10", str(path)]
    subprocess.run([ffmpeg, "-y", "-loglevel", "error", *source, *encode], check=True, timeout=120)
    proc = subprocess.run([sys.executable, "-c", _PEAK_8K, str(path)], capture_output=True, text=True,
                          timeout=300, check=True)  # fmt: skip
    chunks, frames, peak_kib = (int(v) for v in proc.stdout.split())
    assert (chunks, frames) == (12, 12)
    assert peak_kib < 3 * 1024 * 1024, f"peak {peak_kib / 1024:.0f} MiB"  # 12 frames held at once: 5.5 GB
