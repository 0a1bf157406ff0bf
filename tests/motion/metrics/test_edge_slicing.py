"""The ``edge`` protocol cuts motion and music exactly as [EDGE]'s data/slice.py does.

The reference rules are transcribed here from Stanford-TML/EDGE data/slice.py (test split: stride 2.5 s,
length 5 s) and dataset/dance_dataset.py:

- ``slice_motion``: on the 60 fps motion, ``window = int(5 * 60)``, ``stride = int(2.5 * 60)``, starts
  ``0, 150, ...`` kept ``while start <= T - window and count < num_slices`` (``num_slices``: the audio
  slices of the track); each slice is then taken every second frame (``[:, ::2]``, 60 -> 30 fps).
- ``slice_audio``: at the file's own rate ``sr``, ``window = int(5 * sr)``, ``stride = int(2.5 * sr)``,
  starts kept ``while start <= len(audio) - window``; motion slice ``i`` pairs with audio slice ``i``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import soundfile as sf

from skeleton_mamba.tasks.motion.metrics.beat_align import sequence_beat_align
from skeleton_mamba.tasks.motion.metrics.protocols import get_protocol


def edge_slice_motion_starts(num_frames: int, num_slices: float = math.inf) -> list[int]:
    """EDGE ``slice_motion``'s slice starts (60 fps frames), transcribed."""
    window, stride_step = int(5 * 60), int(2.5 * 60)
    starts, start_idx = [], 0
    while start_idx <= num_frames - window and len(starts) < num_slices:
        starts.append(start_idx)
        start_idx += stride_step
    return starts


def edge_slice_audio_count(num_samples: int, sr: int) -> int:
    """EDGE ``slice_audio``'s slice count, transcribed."""
    window, stride_step = int(5 * sr), int(2.5 * sr)
    count, start_idx = 0, 0
    while start_idx <= num_samples - window:
        count += 1
        start_idx += stride_step
    return count


def frame_coded(num_frames: int) -> np.ndarray:
    """``(T, 24, 3)`` joints whose x coordinate of joint 0 is the frame index (clip starts are readable)."""
    rng = np.random.default_rng(num_frames)
    joints = rng.normal(scale=0.1, size=(num_frames, 24, 3))
    joints[:, 0, 0] = np.arange(num_frames)
    return joints


def test_edge_clips_equal_slice_motion_for_every_60fps_length():
    protocol = get_protocol("edge")
    for t in range(300, 1301):
        joints = frame_coded(t)
        clips = protocol.score(joints, 60.0, None)
        starts = edge_slice_motion_starts(t)
        assert len(clips) == len(starts), f"T = {t}: {len(clips)} clips, EDGE cuts {len(starts)}"
        for clip, start in zip(clips, starts, strict=True):
            expected = np.arange(start, start + 300, 2, dtype=np.float64)  # pos[s : s + 300][::2]
            np.testing.assert_array_equal(clip.joints[:, 0, 0].numpy(), expected, err_msg=f"T = {t}")


@pytest.mark.parametrize("t", [599, 749, 899, 1049, 1199])
def test_edge_lengths_300_plus_150k_minus_1_lose_the_last_half_window(t):
    # 30 fps has ceil(t / 2) frames, enough for one more 150-frame clip; EDGE's 60 fps rule has not
    clips = get_protocol("edge").score(frame_coded(t), 60.0, None)
    assert len(clips) == (t + 1 - 300) // 150


def test_edge_clips_at_30fps_follow_the_same_rule_in_seconds():
    protocol = get_protocol("edge")
    for t in range(150, 651):
        clips = protocol.score(frame_coded(t), 30.0, None)
        assert len(clips) == len(edge_slice_motion_starts(2 * t)), t  # 2t frames at 60 fps: same seconds


def test_edge_pairs_clip_i_with_audio_slice_i_and_stops_at_the_shorter():
    protocol = get_protocol("edge")
    t = 1199  # EDGE: 6 motion slices
    joints = frame_coded(t)
    rng = np.random.default_rng(0)
    for num_audio in range(1, 9):
        beats = [np.sort(rng.choice(150, size=8, replace=False)) for _ in range(num_audio)]
        clips = protocol.score(joints, 60.0, beats)
        starts = edge_slice_motion_starts(t, num_audio)
        assert len(clips) == len(starts)
        for i, (clip, start) in enumerate(zip(clips, starts, strict=True)):
            truth = sequence_beat_align(joints[start : start + 300 : 2], beats[i], "bailando", 30.0)
            assert clip.beat_align == pytest.approx(truth, abs=1e-12)


def test_edge_audio_slice_starts_follow_slice_audio():
    from skeleton_mamba.tasks.motion.music.protocol_music import edge_slice_starts

    for sr in (8000, 22050, 44100, 44101, 48000):
        window = int(5 * sr)
        for n in [0, window - 1, window, window + 1] + [window + k * int(2.5 * sr) + d for k in (1, 2, 5)
                                                        for d in (-1, 0, 1)]:  # fmt: skip
            starts = edge_slice_starts(n, sr)
            assert len(starts) == edge_slice_audio_count(n, sr), (sr, n)
            assert list(starts) == [i * int(2.5 * sr) for i in range(len(starts))]


@pytest.mark.parametrize("extra", [-1, 0])
def test_edge_music_slices_pair_with_motion_of_the_same_duration(tmp_path, extra):
    """A 10 s track cut 1 sample short gives 2 slices, a full one 3: as EDGE, and as the motion of 10 s."""
    from skeleton_mamba.tasks.motion.music.protocol_music import edge_slice_features

    sr = 8000
    n = 10 * sr + extra
    rng = np.random.default_rng(1)
    audio = 0.1 * rng.standard_normal(n)
    clicks = np.arange(0, n, sr // 2)  # 120 BPM clicks, so every slice has beats
    audio[clicks] = 0.9
    path = tmp_path / "track.wav"
    sf.write(path, audio, sr)
    features = edge_slice_features(path, cache_dir=tmp_path / "cache", use_cache=False)
    assert len(features) == edge_slice_audio_count(n, sr)
    motion_frames = 600 + extra  # the same duration at 60 fps
    clips = get_protocol("edge").score(frame_coded(motion_frames), 60.0, None)
    assert len(clips) == len(features) == len(edge_slice_motion_starts(motion_frames))
