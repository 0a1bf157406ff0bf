"""Music features, tempo on the real tracks, the feature cache and ``sm analyze-music``."""

from __future__ import annotations

import json
import shutil

import librosa
import numpy as np
import pytest
import soundfile as sf

from skeleton_mamba.tasks.motion.commands.analyze_music import main as analyze_main
from skeleton_mamba.tasks.motion.io.cache import FeatureCache
from skeleton_mamba.tasks.motion.music import features as music
from skeleton_mamba.tasks.motion.music.features import (
    BEAT,
    CHROMA,
    ENVELOPE,
    MFCC,
    OCTAVE_AMBIGUITY,
    ONSET_PEAK,
    aist_start_bpm,
    compute_music_features,
    extract_music_features,
    fold_tempo,
    load_audio,
    tempo_octaves,
)
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.music import click_track

REAL_TRACKS = {  # file stem -> listed tempo (shared/data/music/LICENSE-MUSIC.txt)
    "energetic_acoustic_1": 132.0,
    "happy_electronic_1": 123.0,
    "energetic_electronic_2": 150.0,
}


@pytest.fixture(scope="module")
def real_analyses(shared_data, tmp_path_factory):
    """60-fps analyses of the three real tracks (three beat-tracking calls for the whole module)."""
    folder = shared_data / "music"
    if not folder.is_dir():
        pytest.skip(f"real music not found at {folder}")
    cache = tmp_path_factory.mktemp("music_cache")
    return {
        name: extract_music_features(folder / f"{name}.opus", fps=60, cache_dir=cache) for name in REAL_TRACKS
    }


@pytest.mark.parametrize("name", sorted(REAL_TRACKS))
def test_tempo_of_real_music_within_3_percent(real_analyses, name):
    analysis = real_analyses[name]
    assert analysis.tempo_bpm == pytest.approx(REAL_TRACKS[name], rel=0.03)
    assert analysis.features.shape[1] == 35
    # Beats are about one period apart (no half/double-tempo beat grid).
    period = np.median(np.diff(analysis.beat_times))
    assert 60.0 / period == pytest.approx(REAL_TRACKS[name], rel=0.03)


def test_start_bpm_from_aist_names_and_tempo_fold():
    assert aist_start_bpm("mBR0") == 80
    assert aist_start_bpm("mHO5.wav") == 135
    assert aist_start_bpm("mJB5") == 130
    assert aist_start_bpm("gHO_sBM_cAll_d19_mHO5_ch02") == 135
    assert aist_start_bpm("gKR_sBM_cAll_d28_mKR2_ch02.pkl") == 100
    assert aist_start_bpm("happy_electronic_1") is None
    assert fold_tempo(66.0) == 132.0  # half tempo -> dance octave
    assert fold_tempo(300.0) == 150.0  # double tempo
    assert fold_tempo(123.0) == 123.0
    with pytest.raises(ValueError):
        fold_tempo(120.0, (100.0, 150.0))


@pytest.mark.parametrize("fps", [60, 30])
def test_feature_columns_match_librosa_called_directly(shared_data, fps):
    path = shared_data / "music" / "happy_electronic_1.opus"
    sr = fps * 512
    y, _ = librosa.load(path, sr=sr, duration=10.0)
    analysis = compute_music_features(y, fps=fps, start_bpm=123.0)
    feats = analysis.features
    t_len = 1 + len(y) // 512
    assert feats.shape == (t_len, 35) and feats.dtype == np.float32

    envelope = librosa.onset.onset_strength(y=y, sr=sr)
    np.testing.assert_allclose(feats[:, ENVELOPE], envelope, rtol=1e-5, atol=1e-6)
    mfcc = librosa.feature.mfcc(y=y, sr=sr, n_mfcc=20).T
    np.testing.assert_allclose(feats[:, MFCC], mfcc, rtol=1e-4, atol=1e-3)
    chroma = librosa.feature.chroma_cens(y=y, sr=sr, hop_length=512, n_chroma=12).T
    np.testing.assert_allclose(feats[:, CHROMA], chroma, rtol=1e-5, atol=1e-6)
    peaks = librosa.onset.onset_detect(onset_envelope=envelope, sr=sr, hop_length=512)
    np.testing.assert_array_equal(np.flatnonzero(feats[:, ONSET_PEAK]), peaks)
    _, beats = librosa.beat.beat_track(
        onset_envelope=envelope, sr=sr, hop_length=512, start_bpm=123.0, tightness=100
    )
    np.testing.assert_array_equal(np.flatnonzero(feats[:, BEAT]), beats)
    np.testing.assert_array_equal(analysis.beat_frames, beats)
    assert set(np.unique(feats[:, [ONSET_PEAK, BEAT]])) <= {0.0, 1.0}


def test_octave_prior_is_soft(tmp_path):
    # A 60 BPM click track: folded to 120 BPM, the prior still lets the clicks' evidence keep 60 BPM beats.
    sr = 30 * 512
    click_track(tmp_path / "slow.wav", bpm=60.0, seconds=12.0, sr=sr)
    y, _ = librosa.load(tmp_path / "slow.wav", sr=sr)
    analysis = compute_music_features(y, fps=30, bpm_range=music.DANCE_BPM_RANGE)
    assert analysis.tempo_bpm == pytest.approx(60.0, rel=0.03)
    phase = analysis.beat_times - 0.5  # clicks at 0.5 s + k s
    assert np.abs(phase - np.round(phase)).max() < 0.05


def test_cache_hit_miss_and_content_key(tmp_path, monkeypatch):
    wav = tmp_path / "clicks.wav"
    click_track(wav)
    cache_dir = tmp_path / "cache"
    first = extract_music_features(wav, fps=30, cache_dir=cache_dir)
    assert len(list(cache_dir.glob("*.npy"))) == 1
    assert first.tempo_bpm == pytest.approx(120.0, rel=0.03)

    def no_compute(*args, **kwargs):
        raise AssertionError("cache hit expected, features were recomputed")

    monkeypatch.setattr(music, "compute_music_features", no_compute)
    hit = extract_music_features(wav, fps=30, cache_dir=cache_dir)
    np.testing.assert_array_equal(hit.features, first.features)
    np.testing.assert_array_equal(hit.beat_frames, first.beat_frames)
    assert hit.tempo_bpm == first.tempo_bpm and hit.duration_s == first.duration_s
    renamed = tmp_path / "renamed.wav"
    shutil.copy(wav, renamed)
    extract_music_features(renamed, fps=30, cache_dir=cache_dir)  # same content: still a hit
    monkeypatch.undo()

    extract_music_features(wav, fps=60, cache_dir=cache_dir)  # other settings: miss
    assert len(list(cache_dir.glob("*.npy"))) == 2
    click_track(wav, bpm=100.0)  # other content: miss
    extract_music_features(wav, fps=30, cache_dir=cache_dir)
    assert len(list(cache_dir.glob("*.npy"))) == 3
    extract_music_features(wav, fps=30, cache_dir=cache_dir, use_cache=False)
    assert len(list(cache_dir.glob("*.npy"))) == 3
    assert not list(cache_dir.glob("*.tmp"))


def test_cache_writes_are_atomic_and_corrupt_entries_recompute(tmp_path, monkeypatch):
    cache = FeatureCache("music", tmp_path)

    def crash(file, *args, **kwargs):
        file.write(b"\x93NUMPY half written")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "save", crash)
    with pytest.raises(KeyboardInterrupt):
        cache.store("abc", np.ones(3))
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []  # neither the entry nor the temporary file
    assert cache.load("abc") is None and cache.misses == 1

    cache.store("abc", np.arange(4.0))
    np.testing.assert_array_equal(cache.load("abc"), np.arange(4.0))
    assert cache.hits == 1
    cache.path_for("abc").write_bytes(b"garbage")
    with pytest.warns(UserWarning, match="unreadable cache entry"):
        assert cache.load("abc") is None


def test_analyze_music_cli_json_and_out(tmp_path, capsys):
    wav = tmp_path / "clicks.wav"
    click_track(wav)
    out = tmp_path / "feats.npy"
    cache = str(tmp_path / "c")
    rc = analyze_main([str(wav), "--fps", "30", "--json", "--out", str(out), "--cache-dir", cache])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    keys = {"file", "duration_s", "tempo_bpm", "dance_tempo_bpm", "dance_bpm_range", "beats_s", "fps"}
    assert set(report) == keys | {"feature_shape", "audio_stack", "tempo_octaves", "tempo_ambiguous"}
    # a click every beat: the tracker's octave is the strongest, half and double it clearly weaker
    octaves = report["tempo_octaves"]
    assert octaves[0]["bpm"] == pytest.approx(report["tempo_bpm"], rel=1e-3) and not report["tempo_ambiguous"]
    assert all(o["strength"] < OCTAVE_AMBIGUITY * octaves[0]["strength"] for o in octaves[1:])
    assert report["fps"] == 30 and report["duration_s"] == pytest.approx(8.0)
    assert report["tempo_bpm"] == pytest.approx(120.0, rel=0.03)
    feats = np.load(out)
    assert list(feats.shape) == report["feature_shape"] and feats.shape == (1 + int(8.0 * 15360) // 512, 35)
    np.testing.assert_allclose(report["beats_s"], np.flatnonzero(feats[:, BEAT]) / 30, atol=1e-4)
    # Clicks start at 0.5 s, every 0.5 s: beats sit on them (within 0.05 s).
    phase = (np.array(report["beats_s"]) - 0.5) / 0.5
    assert np.abs(phase - np.round(phase)).max() < 0.1

    assert analyze_main([str(wav), "--fps", "30", "--no-cache"]) == 0
    assert "BPM" in capsys.readouterr().out


def test_analyze_music_prints_both_octaves_of_a_slow_track_with_busy_eighths(tmp_path, capsys):
    """A 68 BPM kick with a hi-hat on every eighth note: half the periods hold a kick, so 68 and 136 BPM both
    fit; the tracker (prior about 120 BPM) reads one of them, and both are printed with their strengths."""
    sr, seconds, bpm = 22050, 20.0, 68.0
    y = np.zeros(int(seconds * sr), dtype=np.float32)
    n = np.arange(int(0.12 * sr))
    kick = 0.9 * np.sin(2 * np.pi * 55 * n / sr) * np.exp(-n / 1500)
    hat = (
        0.5
        * np.random.default_rng(0).standard_normal(int(0.04 * sr))
        * np.exp(-np.arange(int(0.04 * sr)) / 150)
    )
    for k, start in enumerate(np.arange(0.5, seconds - 0.2, 30.0 / bpm)):
        i = int(start * sr)
        y[i : i + hat.size] += hat.astype(np.float32)
        if k % 2 == 0:
            y[i : i + kick.size] += kick.astype(np.float32)
    wav = tmp_path / "slow.wav"
    sf.write(wav, y, sr)
    assert analyze_main([str(wav), "--json", "--no-cache"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["tempo_ambiguous"]
    bpms = sorted(o["bpm"] for o in report["tempo_octaves"][:2])
    assert bpms[1] == pytest.approx(2 * bpms[0], abs=0.002) and bpms[0] == pytest.approx(bpm, rel=0.03)
    assert analyze_main([str(wav), "--no-cache"]) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if l.startswith("tempo octaves"))
    assert f"{bpms[0]:.1f} BPM" in line and f"{bpms[1]:.1f} BPM" in line and "--start-bpm" in line


def test_tempo_octaves_of_envelopes():
    fps = 60
    pulse = np.zeros(1800)
    pulse[::30] = 1.0  # 120 BPM
    octaves = dict(tempo_octaves(pulse, fps, 120.0))
    assert octaves[120.0] == pytest.approx(1.0, abs=0.01)  # perfectly periodic, at the prior's centre
    assert octaves[240.0] == 0.0  # between the pulses: anti-correlated, clipped at 0
    assert octaves[60.0] == pytest.approx(np.exp(-0.5), abs=0.01)  # periodic too, weighed down by the prior
    assert tempo_octaves(np.zeros(1800), fps, 120.0) == []  # silence: no strength anywhere


def test_bad_audio_inputs_name_the_file(tmp_path, capsys):
    missing = tmp_path / "missing.wav"
    with pytest.raises(FileNotFoundError, match="missing.wav"):
        load_audio(missing, 22050)
    bad = tmp_path / "bad.wav"
    bad.write_bytes(b"not audio at all")
    with pytest.raises(ValueError, match="bad.wav: cannot decode audio"):
        load_audio(bad, 22050)
    assert sm_main(["analyze-music", str(bad), "--no-cache"]) == 2
    assert "bad.wav" in capsys.readouterr().err


def test_detected_tempo_and_the_dance_range_fold_are_separate(monkeypatch):
    """The beat tracker's prior is librosa's estimate as detected (EDGE's fallback), not folded."""
    priors = []
    real_beat_track = librosa.beat.beat_track

    def recording(**kwargs):
        priors.append(kwargs["start_bpm"])
        return real_beat_track(**kwargs)

    monkeypatch.setattr(librosa.feature, "tempo", lambda **kwargs: np.array([68.0]))
    monkeypatch.setattr(librosa.beat, "beat_track", recording)
    y = np.random.default_rng(0).normal(0, 0.1, 4 * 15360).astype(np.float32)
    compute_music_features(y, fps=30)
    compute_music_features(y, fps=30, bpm_range=music.DANCE_BPM_RANGE)
    assert priors == [68.0, 136.0]
    # Hand-placed beats every 0.9 s (66.67 BPM): tempo as detected, the fold only in its own field.
    features = np.zeros((600, 35), np.float32)
    features[:, ENVELOPE] = 1.0
    features[np.arange(10, 600, 27), BEAT] = 1.0  # 27 frames at 30 fps = 0.9 s
    analysis = music.MusicAnalysis.from_features(features, 30, 20.0)
    assert analysis.tempo_bpm == pytest.approx(60.0 / 0.9, rel=1e-9)
    assert analysis.dance_tempo_bpm == pytest.approx(2 * 60.0 / 0.9, rel=1e-9)
    assert analysis.tempo_note is None


def test_no_tempo_says_why(tmp_path, capsys):
    sr = 22050
    sf.write(tmp_path / "silence.wav", np.zeros(5 * sr, np.float32), sr)
    sf.write(tmp_path / "blip.wav", np.random.default_rng(0).normal(0, 0.1, sr // 10).astype(np.float32), sr)
    assert analyze_main([str(tmp_path / "silence.wav"), "--no-cache"]) == 0
    assert "no tempo: the audio is silent" in capsys.readouterr().out
    assert analyze_main([str(tmp_path / "blip.wav"), "--no-cache", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["tempo_bpm"] is None and report["dance_tempo_bpm"] is None
    assert report["tempo_note"].startswith("the audio is too short for a tempo (0.10 s")
    steady = np.zeros((600, 35), np.float32)
    steady[:, ENVELOPE] = 1.0
    steady[300, BEAT] = 1.0
    assert music.MusicAnalysis.from_features(steady, 30, 20.0).tempo_note.startswith("no steady beat")


def test_analyze_music_out_of_range_samples_and_out_paths(tmp_path, capsys):
    sr = 22050
    huge = tmp_path / "huge.wav"
    sf.write(huge, np.full(2 * sr, 1e30, np.float32), sr, subtype="FLOAT")
    assert sm_main(["analyze-music", str(huge), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "huge.wav: samples out of range" in err and len(err.strip().splitlines()) == 1
    wav = tmp_path / "clicks.wav"
    click_track(wav, seconds=4.0)
    folder = tmp_path / "adir"
    folder.mkdir()
    assert sm_main(["analyze-music", str(wav), "--no-cache", "--out", str(folder)]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert sm_main(["analyze-music", str(wav), "--no-cache", "--out", str(tmp_path / "feats")]) == 2
    assert "must end in .npy" in capsys.readouterr().err
    assert not (tmp_path / "adir.npy").exists() and not (tmp_path / "feats.npy").exists()
    out = tmp_path / "sub" / "f.npy"
    assert analyze_main([str(wav), "--no-cache", "--out", str(out)]) == 0
    assert f"-> {out}" in capsys.readouterr().out and np.load(out).shape[1] == 35
    assert sorted(p.name for p in out.parent.iterdir()) == ["f.npy"]  # no temporary file left
