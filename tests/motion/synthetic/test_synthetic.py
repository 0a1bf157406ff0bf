"""Synthetic dance and music generators (demo data without AIST++)."""

from __future__ import annotations

import numpy as np
import pytest
import soundfile as sf
import torch
from scipy.signal import argrelmin

from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics_axis_angle
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.synthetic import make_demo_set
from skeleton_mamba.tasks.motion.synthetic.dance import STYLES, synthesize_dance
from skeleton_mamba.tasks.motion.synthetic.music import beat_times, synthesize_music


def _speed(motion) -> np.ndarray:
    """Central-difference speed per frame (T,), mean over joints, of the toolkit's FK positions."""
    joints = smpl_forward_kinematics_axis_angle(
        torch.from_numpy(motion.poses).double(), torch.from_numpy(motion.root_position()).double()
    ).numpy()
    speed = np.zeros(len(joints))
    speed[1:-1] = np.linalg.norm(joints[2:] - joints[:-2], axis=-1).mean(axis=1) / 2
    return speed


def test_swing_side_music_fixes_the_side_of_the_two_beat_swing():
    from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix, matrix_to_euler

    def swing(seed: int, swing_side: str) -> float:
        """Left shoulder's z angle (deg) on beat 0 minus beat 1 of an "arms" dance: 2 * scale * side * 50."""
        motion = synthesize_dance(120.0, 1.0, 30.0, "arms", seed, swing_side)  # beat 1 at frame 15
        z = matrix_to_euler(axis_angle_to_matrix(torch.from_numpy(motion.poses[[0, 15], 16])), "XYZ")[:, 2]
        return float(np.degrees(z[0] - z[1]))

    music = [swing(seed, "music") for seed in range(8)]
    assert all(2 * 0.8 * 50 - 1e-6 <= d <= 2 * 1.2 * 50 + 1e-6 for d in music)  # always the listed side
    drawn = [swing(seed, "random") for seed in range(8)]
    assert min(drawn) < 0 < max(drawn)  # the default draws it per seed
    # the seed's amplitude is the same either way
    assert sorted(abs(d) for d in drawn) == pytest.approx(sorted(music), abs=1e-6)
    with pytest.raises(ValueError, match="swing side"):
        synthesize_dance(120.0, 1.0, 30.0, "arms", 0, "left")


@pytest.mark.parametrize("style", sorted(STYLES))
def test_dance_velocity_minima_fall_on_beats(style):
    fps, bpm = 60.0, 120.0  # a beat every 30 frames
    motion = synthesize_dance(bpm, 6.0, fps, style, seed=3)
    speed = _speed(motion)
    beats = np.arange(30, len(speed) - 1, 30)
    # every joint is at rest on every beat
    assert speed[beats].max() < 1e-6 * speed.max()
    # and the body moves in between: the clear minima of the speed are exactly the beats
    minima = argrelmin(speed[1:-1], order=3)[0] + 1
    deep = minima[speed[minima] < 0.05 * speed.max()]
    assert set(deep) == set(beats)


def test_dance_off_grid_tempo_minima_within_a_frame():
    fps, bpm = 30.0, 97.0  # beats fall between frames
    speed = _speed(synthesize_dance(bpm, 8.0, fps, "bounce", seed=1))
    minima = argrelmin(speed[1:-1], order=3)[0] + 1
    beats = np.arange(1, int(8.0 * bpm / 60)) * 60 / bpm * fps  # fractional beat frames
    inside = beats[(beats > 2) & (beats < len(speed) - 3)]
    nearest = np.abs(minima[:, None] - inside[None]).min(axis=0)
    assert nearest.max() <= 1.0


def test_dance_format_and_errors(tmp_path):
    motion = synthesize_dance(100, 2.0, 30, "sway", 0)
    assert motion.poses.shape == (60, 24, 3) and motion.trans.shape == (60, 3) and motion.fps == 30
    with pytest.raises(ValueError, match="unknown dance style"):
        synthesize_dance(100, 2.0, 30, "tango")
    with pytest.raises(ValueError, match="positive"):
        synthesize_dance(-1, 2.0)
    pairs = make_demo_set(tmp_path, count=2, duration_s=1.0, seed=4)
    for motion_path, music_path in pairs:
        assert motion_path.name.startswith("synthetic_") and music_path.stem == motion_path.stem
        assert load_motion(motion_path).num_frames == 30
        audio, sr = sf.read(music_path)
        assert sr == 22050 and len(audio) == 22050


def test_music_has_the_requested_tempo(tmp_path):
    import librosa

    bpm, duration = 128.0, 12.0
    track = synthesize_music(bpm, duration, seed=5)
    assert beat_times(bpm, duration) == pytest.approx(np.arange(0, 12, 60 / bpm))
    path = tmp_path / "track.wav"
    sf.write(path, track.audio, track.sr)
    audio, sr = sf.read(path, dtype="float32")
    # librosa's onset envelope of the written file, then the beat period from its autocorrelation
    hop = 128
    envelope = librosa.onset.onset_strength(y=audio, sr=sr, hop_length=hop)
    acf = librosa.autocorrelate(envelope - envelope.mean())
    lags = np.arange(len(acf)) * hop / sr
    window = (lags > 60 / 170) & (lags < 60 / 70)
    period = lags[window][np.argmax(acf[window])]
    assert 60 / period == pytest.approx(bpm, rel=0.015)
    # the strongest onsets (kicks) line up with the scheduled beats: envelope frames are centred, the
    # detection can lead a sharp attack by up to half an FFT window (2048 / 2 samples = 46 ms)
    times = librosa.times_like(envelope, sr=sr, hop_length=hop)
    top = times[np.argsort(envelope)[-len(track.beats) // 2 :]]
    assert np.abs(top[:, None] - track.beats[None]).min(axis=1).max() < 0.05


def test_stratified_holdout_keeps_each_styles_tempo_range_in_training():
    from skeleton_mamba.tasks.motion.synthetic.splits import parse_demo_name, stratified_holdout

    bpms = {"arms": (93, 103, 133), "bounce": (90, 105, 122), "sway": (92, 98, 116, 130)}
    names = [f"m/synthetic_{s}_{bpm}bpm_s{i}.npz" for s, row in bpms.items() for i, bpm in enumerate(row)]
    split = stratified_holdout(names, val=1, test=2)
    held = [n for n in names if split[n] != "train"]
    assert sorted(split[n] for n in held) == ["test", "test", "val"]
    # one per style, never a style's slowest or fastest, and for 3 dances the middle tempo
    assert sorted(parse_demo_name(n)[0] for n in held) == ["arms", "bounce", "sway"]
    for name in held:
        style, bpm, _ = parse_demo_name(name)
        assert min(bpms[style]) < bpm < max(bpms[style])
        if len(bpms[style]) == 3:
            assert bpm == sorted(bpms[style])[1]
    # a fourth held-out dance can only be sway's other inner tempo; a fifth does not exist
    four = stratified_holdout(names, val=2, test=2)
    assert {n for n, v in four.items() if v != "train"} == set(held) | {"m/synthetic_sway_116bpm_s2.npz"}
    with pytest.raises(ValueError, match="fewer than 3 test \\+ 2 val"):
        stratified_holdout(names, val=2, test=3)
    with pytest.raises(ValueError, match="not a generated demo dance"):
        stratified_holdout(["m/dance.npz"], val=0, test=0)
    assert set(stratified_holdout(names, val=0, test=0).values()) == {"train"}
