"""A long track's music feature analysed in windows (:mod:`...music_windows`) equals the whole-track
analysis within librosa's decibel floor, on a real recording and a synthetic one; long tracks take that
path, and ``duration_s`` analyses only the start."""

from __future__ import annotations

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.music import music_windows
from skeleton_mamba.tasks.motion.music.features import (
    BEAT,
    HOP_LENGTH,
    extract_music_features,
    features_from_frames,
    frame_features,
    load_audio,
)
from skeleton_mamba.tasks.motion.synthetic import synthesize_music
from skeleton_mamba.tasks.motion.synthetic.music import write_music
from tests.helpers.repo import SHARED_DATA

FPS = 30


def _tracks(tmp_path) -> list:
    synthetic = write_music(tmp_path / "synthetic.wav", synthesize_music(124.0, 26.0, sr=22050, seed=5))
    real = sorted((SHARED_DATA / "music").glob("*.opus")) if (SHARED_DATA / "music").is_dir() else []
    return [synthetic, *real[:1]]


def test_windows_with_context_equal_the_whole_track(tmp_path):
    for path in _tracks(tmp_path):
        whole = frame_features(load_audio(path, FPS * HOP_LENGTH), FPS * HOP_LENGTH)
        windowed = music_windows.windowed_frame_features(path, FPS, window_s=8, context_s=3)
        assert [w.shape for w in windowed] == [w.shape for w in whole], path
        envelope, mfcc, chroma = (np.abs(a - b) for a, b in zip(whole, windowed))
        # measured on the shared recording: 0.01 of 9.9, 0.8 of 337 (resampling and the dB floor), 0.04
        assert envelope.max() < 0.005 * np.abs(whole[0]).max() + 0.05, (path, envelope.max())
        assert mfcc.max() < 0.005 * np.abs(whole[1]).max(), (path, mfcc.max())
        assert np.quantile(chroma, 0.99) < 0.03 and chroma.max() < 0.08, (path, chroma.max())
        beats_whole = np.flatnonzero(features_from_frames(*whole, FPS, start_bpm=120.0)[:, BEAT])
        beats_windowed = np.flatnonzero(features_from_frames(*windowed, FPS, start_bpm=120.0)[:, BEAT])
        assert len(beats_whole) == len(beats_windowed)
        assert np.abs(beats_whole - beats_windowed).max() <= 1, path


def test_a_long_track_is_analysed_in_windows_and_a_duration_cuts_the_analysis(tmp_path, monkeypatch):
    path = write_music(tmp_path / "song.wav", synthesize_music(120.0, 20.0, sr=22050, seed=2))
    whole = extract_music_features(path, fps=FPS, cache_dir=tmp_path / "cache")
    calls = []
    real = music_windows.windowed_frame_features
    monkeypatch.setattr(music_windows, "LONG_TRACK_S", 10.0)
    monkeypatch.setattr(
        music_windows, "windowed_frame_features", lambda *a, **k: calls.append(a) or real(*a, **k)
    )
    windowed = extract_music_features(path, fps=FPS, cache_dir=tmp_path / "cache")
    assert len(calls) == 1 and windowed.features.shape == whole.features.shape  # not the short track's cache
    assert windowed.tempo_bpm == pytest.approx(whole.tempo_bpm, abs=1.0)
    first = extract_music_features(path, fps=FPS, cache_dir=tmp_path / "cache", duration_s=5.0)
    assert len(calls) == 1  # 5 s: short, analysed whole
    assert abs(len(first.features) - 5 * FPS) <= 1 and first.duration_s == 5.0
    with pytest.raises(ValueError, match="duration_s must be positive"):
        extract_music_features(path, fps=FPS, duration_s=0.0)


def test_the_tempogram_summed_in_chunks_is_librosas_mean_and_gives_the_same_beats(tmp_path):
    import librosa

    for path in _tracks(tmp_path):
        envelope, mfcc, chroma = frame_features(load_audio(path, FPS * HOP_LENGTH), FPS * HOP_LENGTH)
        ours = music_windows.mean_tempogram(envelope, FPS, chunk=100)
        tempogram = librosa.feature.tempogram(
            onset_envelope=envelope, sr=FPS * HOP_LENGTH, win_length=len(ours)
        )
        theirs = tempogram.mean(axis=1)  # the window librosa.feature.tempo uses: 8 s
        np.testing.assert_allclose(ours[:, 0], theirs, rtol=1e-6, atol=1e-9)
        for start_bpm in (None, 100.0):
            direct = features_from_frames(envelope, mfcc, chroma, FPS, start_bpm)
            summed = features_from_frames(envelope, mfcc, chroma, FPS, start_bpm, tempogram=ours)
            np.testing.assert_array_equal(direct[:, BEAT], summed[:, BEAT])


def test_sm_dance_analyses_only_the_music_its_video_covers(tmp_path, monkeypatch, capsys):
    """A long track with a 3 s video: the music is analysed for the video's 3 s (and one more), not whole."""
    import subprocess
    from types import SimpleNamespace

    import imageio_ffmpeg

    from skeleton_mamba.tasks.egodance import dance_inputs
    from skeleton_mamba.tasks.egodance.video_features import VideoFeatures

    song = write_music(tmp_path / "song.wav", synthesize_music(120.0, 40.0, sr=22050, seed=1))
    video = tmp_path / "take.mp4"
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-f", "lavfi", "-i",
                    "testsrc=size=64x64:rate=30", "-frames:v", "90", str(video)], check=True)  # fmt: skip
    analysed = []
    real = dance_inputs.extract_music_features
    monkeypatch.setattr(
        dance_inputs,
        "extract_music_features",
        lambda *a, **k: analysed.append(k["duration_s"]) or real(*a, **k),
    )
    monkeypatch.setattr(
        dance_inputs,
        "_encode",
        lambda path, module, model, frames, *rest: VideoFeatures(num_frames=min(frames, 90)),
    )
    module = SimpleNamespace(hparams=SimpleNamespace(fps=30, image_size=32))
    model = SimpleNamespace(vision_encoder=object())
    inputs = dance_inputs.track_inputs(str(song), str(video), module, model, None, estimate=False, fov=None)
    assert analysed == [pytest.approx(4.0)]  # 90 frames at 30 fps, and a second more
    assert inputs.music.shape[0] == 90
    assert "the dance covers the first 3.0 s" in capsys.readouterr().err
