"""Named dance-evaluation protocols (fact | bailando | edge) on hand-placed motions and beats.

Every expected value is computed here from the placed beats with the published formulas
(``exp(-d^2 / (2 sigma^2))`` averaged over motion beats for FACT, over music beats for Bailando), not by
the code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import soundfile as sf
import torch
from scipy import linalg

from skeleton_mamba.tasks.motion.metrics import BeatAlign
from skeleton_mamba.tasks.motion.metrics.beat_align import kinematic_beats
from skeleton_mamba.tasks.motion.metrics.evaluation import DanceEvaluation
from skeleton_mamba.tasks.motion.metrics.protocols import get_protocol
from skeleton_mamba.tasks.motion.music.features import BEAT, compute_music_features
from tests.helpers.motions import published_kinetic, rest_pose
from tests.helpers.music import click_track


def v_motion(speeds: np.ndarray) -> np.ndarray:
    """(len(speeds) + 1, 24, 3): the rest pose moving along x by ``speeds[k]`` from frame k to k+1."""
    x = np.concatenate([[0.0], np.cumsum(speeds)])
    out = np.repeat(rest_pose()[None], len(x), axis=0)
    out[:, :, 0] += x[:, None]
    return out


def speeds_with_minima(length: int, minima: list[int], floor=0.01, slope=1e-3) -> np.ndarray:
    """Speeds ``floor + slope * distance to the nearest placed minimum``: strict minima exactly there."""
    k = np.arange(length)[:, None]
    return floor + slope * np.abs(k - np.asarray(minima)[None]).min(axis=1)


def gauss(d: float, sigma: float) -> float:
    return math.exp(-(d**2) / (2 * sigma**2))


# ------------------------------------------------------------------------------------------ FACT


def test_fact_protocol_generated_scores_from_frame_120_and_keeps_beats_past_the_end():
    # FACT envelope e_t = |p_t - p_(t-1)| summed over joints (e_0 = 0) = 24 * speeds[t - 1]:
    # strict minima (order 10) at frames m where speeds[m - 1] is a placed minimum.
    motion_minima = [40, 130, 170, 196]  # frame indices; 196 sits 3 frames before the end
    joints = v_motion(speeds_with_minima(199, [m - 1 for m in motion_minima]))  # T = 200
    assert list(kinematic_beats(joints, "fact")) == motion_minima
    music = np.array([42, 128, 150, 175, 201, 260])  # 201 and 260 are past the motion's end (T = 200)
    protocol = get_protocol("fact")
    (clip,) = protocol.score(joints, 60, music, generated=True)
    # Only motion beats >= 120 count (130, 170, 196); music beats >= 120 of the whole track, 201 included.
    expected = np.mean([gauss(2, 3), gauss(5, 3), gauss(5, 3)])  # 130-128, 170-175, 196-201
    assert clip.beat_align == pytest.approx(expected, rel=1e-12)
    cut = np.mean([gauss(2, 3), gauss(5, 3), gauss(21, 3)])  # beats cut at T: 196 -> 175
    assert abs(expected - cut) > 0.05
    torch.testing.assert_close(clip.joints, torch.as_tensor(joints[120:], dtype=torch.float64))
    # Real motion: full length for FID, beats from frame 0 cut to the motion.
    (real,) = protocol.score(joints, 60, music, generated=False)
    assert real.joints.shape[0] == 200
    expected_real = np.mean([gauss(2, 3), gauss(2, 3), gauss(5, 3), gauss(21, 3)])  # 40-42, 130-128, ...
    assert real.beat_align == pytest.approx(expected_real, rel=1e-12)


def test_beat_align_metric_fact_from_frame_120_keeps_the_tracks_beats_by_default():
    motion_minima = [40, 130, 170, 196]
    joints = torch.as_tensor(v_motion(speeds_with_minima(199, [m - 1 for m in motion_minima])))
    music = np.array([42, 128, 150, 175, 201, 260])
    kept, cut = BeatAlign("fact", start_frame=120), BeatAlign("fact", start_frame=120, truncate_music=True)
    kept.update([joints], [music])
    cut.update([joints], [music])
    assert kept.compute().item() == pytest.approx(np.mean([gauss(2, 3), gauss(5, 3), gauss(5, 3)]), rel=1e-12)
    assert cut.compute().item() == pytest.approx(np.mean([gauss(2, 3), gauss(5, 3), gauss(21, 3)]), rel=1e-12)


def test_fact_protocol_resamples_30_fps_motion_to_60():
    joints = v_motion(speeds_with_minima(149, [40, 100]))  # 150 frames at 30 fps
    (clip,) = get_protocol("fact").score(joints, 30, None, generated=False)
    assert clip.joints.shape[0] == 299 and clip.beat_align is None
    torch.testing.assert_close(clip.joints[::2], torch.as_tensor(joints, dtype=torch.float64))
    half = torch.as_tensor((joints[0] + joints[1]) / 2, dtype=torch.float64)
    torch.testing.assert_close(clip.joints[1], half)


# -------------------------------------------------------------------------------------- Bailando


def bailando_speeds(length: int, period: int, first: int) -> tuple[np.ndarray, list[int]]:
    """A symmetric triangle wave of speeds with vertices every ``period`` from ``first`` (Gaussian-safe)."""
    vertices = list(range(first, length - period // 2, period))
    return speeds_with_minima(length, vertices), vertices


def test_bailando_protocol_first_1200_frames_zero_start_and_music_beat_average():
    speeds, vertices = bailando_speeds(1399, 40, 30)  # T = 1400 frames; envelope index k = speed k -> k+1
    joints = v_motion(speeds) + np.array([0.3, 0.0, -0.2])  # root away from the origin at frame 0
    assert list(kinematic_beats(joints, "bailando")) == vertices
    music = np.array([33, 150, 400, 1398, 1500])  # 1398, 1500 are past the envelope (T - 1 = 1399 values)
    protocol = get_protocol("bailando")
    (clip,) = protocol.score(joints, 60, music, generated=True)
    assert clip.joints.shape[0] == 1200
    root0 = joints[0, 0]
    torch.testing.assert_close(clip.joints, torch.as_tensor(joints[:1200] - root0, dtype=torch.float64))
    assert np.allclose(clip.joints[0, 0].numpy(), 0.0)

    def nearest(b):
        return min(abs(b - v) for v in vertices)

    expected = np.mean([gauss(nearest(b), 3) for b in (33, 150, 400, 1398)])  # 1500 dropped, 1398 kept
    assert expected < 0.99  # the placed beats are off the motion beats by different amounts
    assert clip.beat_align == pytest.approx(expected, rel=1e-12)
    (real,) = protocol.score(joints, 60, music, generated=False)
    assert real.joints.shape[0] == 1400  # the real set stays full length, also zero-started
    assert np.allclose(real.joints[0, 0].numpy(), 0.0)


# ------------------------------------------------------------------------------------------ EDGE


def test_edge_protocol_5s_clips_every_2_5s_against_each_slices_own_beats():
    # 30 fps, 225 frames -> clips [0, 150) and [75, 225); Bailando envelope at 30 fps (smoothing 2.5).
    speeds, vertices = bailando_speeds(224, 20, 10)
    joints = v_motion(speeds)
    slice_beats = [np.array([12, 70, 149]), np.array([5, 100])]  # per slice, relative to its start
    protocol = get_protocol("edge")
    clips = protocol.score(joints, 30, slice_beats, generated=True)
    assert len(clips) == 2
    sigma = 1.5  # Bailando's 3 frames at 60 fps, in seconds
    for clip, start, beats in zip(clips, (0, 75), slice_beats, strict=True):
        window = torch.as_tensor(joints[start : start + 150], dtype=torch.float64)
        torch.testing.assert_close(clip.joints, window)
        local = list(kinematic_beats(joints[start : start + 150], "bailando", fps=30))
        # inside a clip the minima are the placed vertices (those away from the clip's edges)
        assert set(local) >= {v - start for v in vertices if start + 5 <= v <= start + 143}
        kept = [b for b in beats if b < 149]  # cut to the clip's envelope length
        expected = np.mean([gauss(min(abs(b - m) for m in local), sigma) for b in kept])
        assert clip.beat_align == pytest.approx(expected, rel=1e-12)
        # PFC of a motion gliding at constant-ish speed with no vertical motion: root acceleration only
        # along x, feet always sliding -> a positive score
        assert clip.pfc > 0
    # 60 fps input: every second frame.
    clips60 = protocol.score(np.repeat(joints, 2, axis=0)[: 2 * 225 - 1], 60, None)
    torch.testing.assert_close(clips60[0].joints, torch.as_tensor(joints[:150], dtype=torch.float64))
    with pytest.raises(ValueError, match="clip needs 150"):
        protocol.score(joints[:100], 30, None)


def test_unknown_protocol_is_refused():
    with pytest.raises(ValueError, match="fact, bailando, edge"):
        get_protocol("lodge")


# ---------------------------------------------------------------------------------- music beats


def test_edge_music_features_are_computed_per_slice(tmp_path):
    import librosa

    wav = tmp_path / "clicks.wav"
    click_track(wav, bpm=120.0, seconds=10.0, sr=22050)
    from skeleton_mamba.tasks.motion.music.protocol_music import edge_slice_features

    slices = edge_slice_features(wav, cache_dir=tmp_path / "cache")
    assert slices.shape == (3, 150, 35)  # 10 s: slices start at 0, 2.5, 5 s (EDGE: start <= len - window)
    # Slice 1, rebuilt by hand: audio [2.5 s, 7.5 s) at the file's rate, 16-bit wav, read at 15,360 Hz.
    audio, sr = sf.read(wav, dtype="float32")
    piece = audio[int(2.5 * sr) : int(2.5 * sr) + int(5.0 * sr)]
    sf.write(tmp_path / "slice1.wav", piece, sr, subtype="PCM_16")
    y, _ = librosa.load(tmp_path / "slice1.wav", sr=15360)
    bpm = float(librosa.feature.tempo(y=librosa.load(tmp_path / "slice1.wav", sr=22050)[0], sr=22050)[0])
    own = compute_music_features(y, 30, start_bpm=bpm, bpm_range=None).features[:150]
    np.testing.assert_allclose(slices[1], own, rtol=1e-5, atol=1e-5)
    beats = get_protocol("edge").music_beats(wav, cache_dir=tmp_path / "cache")
    assert [list(b) for b in beats] == [list(np.flatnonzero(s[:, BEAT])) for s in slices]
    # clicks every 0.5 s = 15 frames: every slice's beats sit on the clicks of that slice
    for b, start_s in zip(beats, (0.0, 2.5, 5.0), strict=True):
        assert len(b) >= 8
        assert np.all(np.abs(((b / 30.0 + start_s) * 2) - np.round((b / 30.0 + start_s) * 2)) * 0.5 < 0.05)


def test_bailando_music_beats_follow_the_clicks_and_window_relative(tmp_path):
    wav = tmp_path / "clicks.wav"
    click_track(wav, bpm=120.0, seconds=8.0, sr=22050)
    protocol = get_protocol("bailando")
    beats = protocol.music_beats(wav, cache_dir=tmp_path / "cache")
    assert len(beats) >= 12
    np.testing.assert_allclose(np.diff(beats), 30, atol=1)  # 120 BPM at 60 fps
    assert np.all(np.abs(beats / 60.0 * 2 - np.round(beats / 60.0 * 2)) * 0.5 < 0.03)  # on a click
    late = protocol.music_beats(wav, start_s=2.0, duration_s=3.0, cache_dir=tmp_path / "cache")
    np.testing.assert_array_equal(late, beats[(beats >= 120) & (beats < 300)] - 120)


# ---------------------------------------------------------------------------------- evaluation


def test_dance_evaluation_fid_uses_the_protocols_frames():
    """FID_k of the evaluation equals the published formula on features of the protocol's frames."""
    rng = np.random.default_rng(0)
    real = [v_motion(rng.uniform(0.0, 0.02, 299)) + rng.normal(0, 0.01, (300, 24, 3)) for _ in range(4)]
    fake = [v_motion(rng.uniform(0.0, 0.03, 299)) + rng.normal(0, 0.01, (300, 24, 3)) for _ in range(3)]
    evaluation = DanceEvaluation("fact")
    for r in real:
        evaluation.add(r, 60, real=True)
    for f in fake:
        evaluation.add(f, 60, np.arange(0, 300, 30))
    out = evaluation.compute()
    kin_real = np.stack([published_kinetic(r, bug=True) for r in real])
    kin_fake = np.stack([published_kinetic(f[120:], bug=True) for f in fake])  # FACT: from frame 120
    mean, std = kin_real.mean(0), kin_real.std(0) + 1e-10
    a, b = (kin_fake - mean) / std, (kin_real - mean) / std
    s1, s2 = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    covmean = linalg.sqrtm(s1 @ s2).real
    fid = ((a.mean(0) - b.mean(0)) ** 2).sum() + np.trace(s1) + np.trace(s2) - 2 * np.trace(covmean)
    assert out["FID_k"] == pytest.approx(fid, rel=1e-4)
    pairs = [np.linalg.norm(a[i] - a[j]) for i in range(3) for j in range(i + 1, 3)]
    assert out["Div_k"] == pytest.approx(np.mean(pairs), rel=1e-9)
    assert out["generated_clips"] == 3 and out["real_clips"] == 4 and "BeatAlign" in out
