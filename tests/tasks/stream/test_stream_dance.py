"""Live music-to-dance: causal features, a tiny trained checkpoint streamed by ``sm stream``.

``sm fit --recipe stream_dance_demo.yaml`` (a few steps on a tiny SYNTHETIC AIST++-layout set) -> a
checkpoint -> ``sm stream`` on a short generated wav (from a file and from standard input) writes the
dance (.npz, .bvh, .mp4) with one pose per complete 30 fps frame of the music; the streamed poses equal
the batch causal forward of the same model on the same features with its own poses teacher-forced.
"""

from __future__ import annotations

import json
import subprocess
import sys

import librosa
import numpy as np
import pytest
import soundfile as sf
import torch

from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.music.features import load_audio
from skeleton_mamba.tasks.motion.synthetic import synthesize_music, write_music
from skeleton_mamba.tasks.stream.audio_input import AudioSource
from skeleton_mamba.tasks.stream.features import HOP, N_FFT, SR, CausalMusicFeatures, music_features
from skeleton_mamba.tasks.stream.live import LiveDancer
from skeleton_mamba.tasks.stream.model import teacher_forcing_inputs
from skeleton_mamba.tasks.stream.module import StreamDanceModule


def _sm(args, cwd, stdin=None) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        [sys.executable, "-m", "skeleton_mamba.tasks", *args], cwd=cwd, capture_output=True, timeout=600,
        input=stdin,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()[-3000:]
    return proc


def test_features_match_librosa_on_windows_that_end_at_each_frame():
    y = np.random.default_rng(0).standard_normal(SR * 2).astype(np.float32) * 0.1
    ours = music_features(y, SR)
    # Independent: librosa's non-centred STFT of the left-padded signal, then its feature functions.
    power = np.abs(librosa.stft(np.pad(y, (N_FFT - HOP, 0)), n_fft=N_FFT, hop_length=HOP, center=False)) ** 2
    logmel = librosa.power_to_db(librosa.feature.melspectrogram(S=power, sr=SR, n_mels=128), top_db=None)
    assert ours.shape == (len(y) // HOP, 34) == (power.shape[1], 34)
    onset = librosa.onset.onset_strength(S=logmel, lag=1, max_size=1, center=False, aggregate=np.mean)
    np.testing.assert_allclose(ours[:, 0], onset, atol=1e-4)
    np.testing.assert_allclose(ours[:, 1:21], librosa.feature.mfcc(S=logmel, n_mfcc=20).T, atol=1e-3)
    chroma = librosa.feature.chroma_stft(S=power, sr=SR, n_fft=N_FFT, tuning=0.0).T
    np.testing.assert_allclose(ours[:, 21:33], chroma, atol=1e-5)
    frames = np.lib.stride_tricks.sliding_window_view(np.pad(y, (N_FFT - HOP, 0)), N_FFT)[::HOP]
    np.testing.assert_allclose(ours[:, 33], np.log(np.sqrt((frames.astype(np.float64) ** 2).mean(1)) + 1e-5),
                               rtol=1e-5)  # fmt: skip


@pytest.mark.parametrize("rate", [SR, 22050])
def test_features_are_causal_and_independent_of_the_chunking(rate):
    y = np.random.default_rng(1).standard_normal(rate * 2).astype(np.float32) * 0.1
    whole = music_features(y, rate, chunk=len(y))
    np.testing.assert_array_equal(music_features(y, rate, chunk=333), whole)
    cut = len(y) // 2
    changed = y.copy()
    changed[cut:] = np.random.default_rng(2).standard_normal(len(y) - cut) * 0.5
    other = music_features(changed, rate)
    # Frames whose window ends before the change do not see it (a 2-frame margin for the resampler's
    # filter, whose half-length is far shorter than 1024 samples).
    safe = int(cut * SR / rate) // HOP - (0 if rate == SR else 2)
    np.testing.assert_array_equal(other[:safe], whole[:safe])
    assert not np.allclose(other[safe + 3 :], whole[safe + 3 :])


def test_bad_audio_is_explained(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        AudioSource(str(tmp_path / "missing.wav"))
    bad = tmp_path / "bad.wav"
    bad.write_bytes(b"not audio")
    with pytest.raises(ValueError, match="bad.wav"):
        AudioSource(str(bad))
    with pytest.raises(ValueError, match="NaN"):
        CausalMusicFeatures().push(np.array([0.0, np.nan], np.float32))


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """A tiny stream-dance checkpoint trained for 3 steps on a tiny synthetic AIST++-layout set."""
    cwd = tmp_path_factory.mktemp("stream_fit")
    _sm([
        "fit", "--recipe", "stream_dance_demo.yaml", "--trainer.max_steps=3", "--trainer.logger=false",
        "--trainer.enable_progress_bar=false", f"--trainer.default_root_dir={cwd}",
        f"--data.init_args.root={cwd / 'data'}", "--data.init_args.synthetic_count=3",
        "--data.init_args.synthetic_duration_s=3.0", "--data.init_args.window_frames=30",
        "--data.init_args.batch_size=2",
    ], cwd)  # fmt: skip
    ckpts = sorted(cwd.rglob("*.ckpt"))
    assert ckpts, "sm fit wrote no checkpoint"
    return ckpts[0]


def test_sm_stream_writes_the_dance_and_equals_the_batch_forward(checkpoint, tmp_path):
    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 2.0, sr=22050, seed=3))
    expected = len(music_features(load_audio(wav, 22050), 22050))
    assert expected == 2 * 30  # two seconds at 30 fps (the resampler flushes at the end)
    args = ["stream", "--ckpt", str(checkpoint), "--music", str(wav)]
    proc = _sm([*args, "--out", str(tmp_path / "live")], tmp_path)
    assert b"audio-to-pose latency" in proc.stdout
    live = tmp_path / "live"
    for suffix in (".npz", ".bvh", ".mp4", "_stream.json"):
        assert (live / f"song{suffix}").is_file(), suffix
    motion = load_motion(live / "song.npz")
    assert motion.num_frames == expected and motion.fps == 30
    report = json.loads((live / "song_stream.json").read_text())
    assert report["frames"] == expected and report["audio_to_pose_latency"]["p99_ms"] > 0

    # In process: the same stream, then the batch causal forward on the streamed inputs.
    model = StreamDanceModule.load_from_checkpoint(checkpoint, map_location="cpu", weights_only=True).model
    source = AudioSource(str(wav), chunk_s=0.02)
    dancer = LiveDancer(model, source.sample_rate)
    for chunk in source:
        dancer.push(chunk.samples, chunk.arrival)
    dancer.push(np.zeros(0, np.float32), last=True)
    tokens, music = dancer.tokens()[None], dancer.music_features()[None]
    assert dancer.beat_phase  # the demo recipe trains with the beat phase: the stream computes it too
    offline = music_features(load_audio(wav, 22050), 22050, beat_phase=True)
    np.testing.assert_array_equal(music[0].numpy(), offline)
    with torch.no_grad():
        batch = model(teacher_forcing_inputs(tokens), music)
    torch.testing.assert_close(tokens, batch, rtol=1e-4, atol=1e-5)
    assert dancer.state.nbytes == model.init_state(1).nbytes

    # The same music as a WAV stream on standard input gives the same dance.
    args = ["stream", "--ckpt", str(checkpoint), "--music", "-", "--no-render"]
    _sm([*args, "--out", str(tmp_path / "stdin")], tmp_path, stdin=wav.read_bytes())
    piped = load_motion(tmp_path / "stdin" / "stdin.npz")
    assert piped.num_frames == expected
    np.testing.assert_allclose(piped.joints, motion.joints, atol=1e-4)


def test_joint_tokens_round_trip_an_smpl_dance():
    from skeleton_mamba.tasks.motion.synthetic import synthesize_dance
    from skeleton_mamba.tasks.stream.model import motion_to_tokens, tokens_to_motion

    dance = synthesize_dance(120.0, 1.0, fps=30.0, style="bounce", seed=0)
    tokens = motion_to_tokens(dance)
    assert tokens.shape == (30, 24, 12)
    # Every joint token carries the root position (metres) in its last three channels.
    np.testing.assert_allclose(tokens[:, 5, 9:].numpy(), dance.root_position(), atol=1e-6)
    back = tokens_to_motion(tokens)
    np.testing.assert_allclose(back.root_position(), dance.root_position(), atol=1e-6)
    np.testing.assert_allclose(back.joint_positions(), dance.joint_positions(), atol=1e-4)


def test_standard_input_as_wav_stream_or_raw_pcm_gives_the_file_samples(tmp_path, monkeypatch):
    import io

    import soundfile as sf

    wav = write_music(tmp_path / "song.wav", synthesize_music(100.0, 0.5, sr=22050, seed=0))
    samples, rate = sf.read(wav, dtype="int16")
    raw = samples.astype("<i2").tobytes()
    for data, raw_rate in ((wav.read_bytes(), None), (raw, rate)):
        monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data)))
        source = AudioSource("-", chunk_s=0.01, raw_rate=raw_rate)
        assert source.sample_rate == rate
        chunks = [c.samples for c in source]
        assert all(len(c) == round(0.01 * rate) for c in chunks[:-1])
        np.testing.assert_array_equal(np.concatenate(chunks), samples / 32768.0)
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(b"garbage bytes")))
    with pytest.raises(ValueError, match="not a WAV stream"):
        AudioSource("-")


def test_sm_stream_explains_missing_inputs(checkpoint, tmp_path, capsys):
    from skeleton_mamba.tasks.training.cli import main

    none = tmp_path / "none.ckpt"
    assert main(["stream", "--ckpt", str(none), "--music", "x.wav", "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"sm stream: error: {none}: No such checkpoint file\n"  # named once
    missing = str(tmp_path / "none.wav")
    assert main(["stream", "--ckpt", str(checkpoint), "--music", missing, "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"sm stream: error: {missing}: music file not found\n"
    assert main(["stream", "--ckpt", str(checkpoint), "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == "sm stream: error: --music FILE (or -) is required for --task dance\n"


def test_sm_stream_checks_checkpoints_like_every_command(tmp_path, capsys, tiny_egodance_module):
    """URLs, text files and checkpoints of another task: one line each, exit 2, nothing written."""
    import lightning

    from skeleton_mamba.tasks.training.cli import main

    out = tmp_path / "out"
    wav = tmp_path / "song.wav"
    sf.write(wav, np.zeros(22050, dtype=np.float32), 22050)
    base = ["--music", str(wav), "--out", str(out)]
    assert main(["stream", "--ckpt", "https://example.org/last.ckpt", *base]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sm stream: error: https://example.org/last.ckpt: remote checkpoints are refused")
    assert err.count("https://example.org/last.ckpt") == 1 and err.count("\n") == 1, err
    text = tmp_path / "notes.ckpt"
    text.write_text("not a checkpoint")
    assert main(["stream", "--ckpt", str(text), *base]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"sm stream: error: {text}: not a plain-data checkpoint, refused"), err
    assert err.count(str(text)) == 1 and err.count("\n") == 1, err
    module = tiny_egodance_module()
    hparams = {**module.hparams, "_class_path": "skeleton_mamba.tasks.egodance.module.EgoDanceModule"}
    ego = tmp_path / "emm.ckpt"
    state = {"state_dict": module.state_dict(), "hyper_parameters": hparams}
    torch.save({**state, "pytorch-lightning_version": lightning.__version__}, ego)
    assert main(["stream", "--ckpt", str(ego), *base]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"sm stream: error: {ego}: holds a skeleton_mamba.tasks.egodance.module.EgoDanceModule, not a "
        "StreamDanceModule (this is an EgoDance checkpoint, not a streaming one)"
    ), err
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())


def test_training_features_are_what_the_live_stream_computes(tmp_path):
    from skeleton_mamba.tasks.motion.synthetic.aistpp_set import write_synthetic_aistpp
    from skeleton_mamba.tasks.stream.data import StreamDanceDataModule

    names = write_synthetic_aistpp(tmp_path, count=2, duration_s=2.0, val_count=1)
    data = StreamDanceDataModule(root=str(tmp_path), train_split="train", val_split="val", window_frames=30)
    assert data.split_names("train") == names[:1] and data.split_names("val") == names[1:]
    motion, music = data.sequence(names[0])
    assert motion.shape == (60, 24, 12) and music.shape == (60, 34)
    source = AudioSource(str(tmp_path / "music" / "mBR0.wav"), chunk_s=0.02)
    live = CausalMusicFeatures(source.sample_rate)
    rows = [live.push(c.samples) for c in source] + [live.push(np.zeros(0, np.float32), last=True)]
    np.testing.assert_array_equal(np.concatenate(rows)[:60], music.numpy())


def test_sm_stream_compile_equals_the_eager_stream(checkpoint, tmp_path, capsys):
    """``--compile``: the frame step through torch.compile (a one-block tiny model: a short compile)."""
    from skeleton_mamba.runtime.compiling import inductor_unavailable
    from skeleton_mamba.tasks.stream.stream_cli import main

    if (reason := inductor_unavailable()) is not None:
        pytest.skip(reason)
    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 1.0, sr=22050, seed=4))
    common = ["--ckpt", str(checkpoint), "--music", str(wav), "--no-render"]
    assert main([*common, "--out", str(tmp_path / "eager")]) == 0
    assert main([*common, "--out", str(tmp_path / "compiled"), "--compile"]) == 0
    err = capsys.readouterr().err
    assert "about a minute" in err and "frame step compiled in" in err
    report = json.loads((tmp_path / "compiled" / "song_stream.json").read_text())
    assert report["compiled"] and report["compile_seconds"] > 0 and report["frames"] == 30
    eager, compiled = (load_motion(tmp_path / d / "song.npz") for d in ("eager", "compiled"))
    np.testing.assert_allclose(compiled.joints, eager.joints, atol=1e-4)


def test_sm_stream_compile_falls_back_to_the_eager_step_with_a_warning(checkpoint, tmp_path, monkeypatch):
    from skeleton_mamba.runtime.compiling import CompiledStep
    from skeleton_mamba.tasks.stream.stream_cli import main

    def no_compiler(self, *args, **kwargs):
        raise RuntimeError("InductorError: CppCompileError: C++ compile error")

    monkeypatch.setattr(CompiledStep, "__call__", no_compiler)
    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 1.0, sr=22050, seed=4))
    args = ["--ckpt", str(checkpoint), "--music", str(wav), "--no-render", "--out", str(tmp_path / "live")]
    with pytest.warns(RuntimeWarning, match="compiling the frame step failed .*running it eagerly"):
        assert main([*args, "--compile"]) == 0
    report = json.loads((tmp_path / "live" / "song_stream.json").read_text())
    assert not report["compiled"] and report["compile_seconds"] is None and report["frames"] == 30


def test_a_stream_slower_than_real_time_suggests_compiling():
    from skeleton_mamba.tasks.stream.stream_cli import realtime_hint

    slow = {"median_ms": 30.0, "p99_ms": 41.0, "max_ms": 60.0}
    fast = {"median_ms": 20.0, "p99_ms": 30.0, "max_ms": 40.0}
    hint = realtime_hint(slow, compiled=False, fps=30)
    assert hint is not None and "41 ms" in hint and "33.3 ms" in hint and "--compile" in hint
    assert realtime_hint(slow, compiled=True, fps=30) is None  # compiling is all the hint could offer
    assert realtime_hint(fast, compiled=False, fps=30) is None
    assert realtime_hint(fast, compiled=False, fps=60) is not None
    assert realtime_hint({k: float("nan") for k in fast}, compiled=False, fps=30) is None
