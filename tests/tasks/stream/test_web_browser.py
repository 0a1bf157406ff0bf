"""``sm export-web``'s page in a real headless Chromium, driven over CDP (:mod:`browser_page`).

Fast: the page opens from disk, makes no request but its own file (and the data URLs inside it), logs no
error, says before any music what it waits for (no NaN on it, the dancer standing in its first pose, not a
lone ball), and onnxruntime-web's wasm steps give the poses that onnxruntime in Python gives for the same
audio (a page of int8 weights, ``--quantize int8``, names its precision and gives the poses of its int8
graph in onnxruntime); a picked file of every format the file picker offers (WAV 16/24-bit/float, 8 to 96
kHz, mono and stereo, FLAC, MP3, Ogg Opus and Vorbis: a few seconds each, written by soundfile, else
ffmpeg, else skipped) dances within seconds, the page saying 'decoding' first and answering throughout; a
file the browser cannot decode is said so, and the page goes on. Slow (``-m slow``): a music file picked
in the page dances as it plays, and its poses, read back, equal ``sm stream``'s on the same WAV within 1
mm; the microphone (Chromium's fake device playing the WAV) dances too. ``SM_WRITE_WEB_PNG=CKPT`` exports
CKPT (e.g. the stream demo's) for the file test and writes the screenshot mid-dance to
``docs/web_dancer.png``.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
import soxr
import torch

from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.music.features import load_audio
from skeleton_mamba.tasks.motion.synthetic import synthesize_music
from skeleton_mamba.tasks.stream.features import HOP, SR, music_features
from skeleton_mamba.tasks.stream.model import tokens_to_motion
from skeleton_mamba.tasks.stream.web_export import export_web_graph
from skeleton_mamba.tasks.stream.web_graph import run_web_graph
from skeleton_mamba.tasks.stream.web_quantize import PRECISIONS, quantize_web_graph
from skeleton_mamba.tasks.training.cli import main as sm
from tests.helpers.browser_page import READY, Page, browser_or_skip, only_local, ort_web_or_skip
from tests.helpers.checkpoint_files import tiny_stream_checkpoint
from tests.helpers.repo import SHARED_DATA

DOCS_PNG = Path(__file__).resolve().parents[3] / "docs" / "web_dancer.png"
EXCERPT_S = 8.0  # of a sample track, danced in real time by the slow tests
JOINT_TOLERANCE_M = 1e-3
WAITING = "pick a music file or press the microphone button"
FORMAT_SECONDS = 3.0  # of each format's file
RESPONSIVE_S = 1.0  # the longest the page may take to answer while it decodes or dances


def music_or_synthetic(seconds: float) -> np.ndarray:
    """Mono audio at SR: the first ``seconds`` of a real sample track, else a synthetic drum track."""
    tracks = sorted((SHARED_DATA / "music").glob("*.opus")) if (SHARED_DATA / "music").is_dir() else []
    if tracks:
        return load_audio(tracks[0], SR)[: int(seconds * SR)]
    return synthesize_music(120.0, seconds, sr=SR, seed=0).audio


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A tiny dancer's checkpoint, its page written by ``sm export-web``, and a 16-bit WAV at SR."""
    browser_or_skip()
    ort_web_or_skip()
    tmp = tmp_path_factory.mktemp("web")
    wav = tmp / "excerpt.wav"
    sf.write(wav, music_or_synthetic(EXCERPT_S), SR, subtype="PCM_16")
    audio = sf.read(wav, dtype="float32")[0]
    ckpt = os.environ.get("SM_WRITE_WEB_PNG")
    dancer = None
    if not ckpt:
        ckpt, dancer = tiny_stream_checkpoint(
            tmp / "dancer.ckpt", torch.from_numpy(music_features(audio, SR))
        )
    assert sm(["export-web", "--ckpt", str(ckpt), "--out", str(tmp / "site")]) == 0
    return tmp / "site" / "index.html", ckpt, dancer, wav, audio


def test_page_opens_from_disk_and_steps_like_onnxruntime(site, tmp_path):
    page_file, ckpt, dancer, _, audio = site
    if dancer is None:
        pytest.skip("SM_WRITE_WEB_PNG is set: the page holds that checkpoint (the slow test uses it)")
    p = Page(page_file.as_uri(), tmp_path)
    try:
        p.wait_for(READY, 120, "the page's start")
        # before any music: what it waits for, a step time measured on silence, no NaN, a whole skeleton
        p.wait_for("document.getElementById('info').textContent.includes('status:')", 10, "the status line")
        info = p.js("document.getElementById('info').textContent")
        assert p.js("window.smDance.status") == "waiting"
        assert f"status: {WAITING}" in info and "ms median (on silence)" in info, info
        assert "NaN" not in p.js("document.body.innerText"), p.js("document.body.innerText")
        shown = np.asarray(p.js("window.smDance.shown"), np.float32).reshape(24, 3)
        assert np.isfinite(shown).all() and np.ptp(shown, axis=0).max() > 0.3, shown  # not one ball
        frames = 45
        poses = _step_page(p, audio, frames)
        assert p.js("window.smDance.threads") == 1  # from disk: not cross-origin isolated
        assert not p.errors, p.errors
        only_local(p.requests)
    finally:
        p.close()
    graph = tmp_path / "dancer.onnx"
    export_web_graph(dancer, graph)
    expected = run_web_graph(graph, dancer, audio[: frames * HOP])["pose"]
    np.testing.assert_allclose(np.asarray(poses).reshape(expected.shape), expected, atol=1e-4)


def _step_page(p: Page, audio: np.ndarray, frames: int) -> list:
    """Step the page's dancer over the first ``frames`` hops of ``audio``; the poses it returns."""
    samples = audio[: frames * HOP].tolist()
    return p.js(
        f"(async () => {{ const x = {samples}; for (let t = 0; t < {frames}; t++) "
        f"await window.smDance.step(x.slice(t * {HOP}, (t + 1) * {HOP})); "
        "return window.smDance.poses; })()"
    )


def test_a_quantized_page_names_its_precision_and_steps_like_onnxruntime(site, tmp_path):
    """``sm export-web --quantize int8``: the page says it runs int8 weights, and its wasm steps (integer
    products) give the poses of the same int8 graph in onnxruntime's Python CPU provider."""
    _, ckpt, dancer, _, audio = site
    if dancer is None:
        pytest.skip("SM_WRITE_WEB_PNG is set: the page holds that checkpoint")
    out = tmp_path / "site"
    assert sm(["export-web", "--ckpt", str(ckpt), "--out", str(out), "--quantize", "int8"]) == 0
    p = Page((out / "index.html").as_uri(), tmp_path)
    try:
        p.wait_for(READY, 120, "the page's start")
        p.wait_for("document.getElementById('info').textContent.includes('status:')", 10, "the status line")
        info = p.js("document.getElementById('info').textContent")
        assert PRECISIONS["int8"] in info and p.js("window.smDance.precision") == PRECISIONS["int8"], info
        frames = 30
        poses = _step_page(p, audio, frames)
        assert not p.errors, p.errors
    finally:
        p.close()
    graph = tmp_path / "dancer.onnx"
    export_web_graph(dancer, graph)
    quantized = quantize_web_graph(graph, tmp_path / "dancer.int8.onnx", "int8")
    expected = run_web_graph(quantized, dancer, audio[: frames * HOP])["pose"]
    np.testing.assert_allclose(np.asarray(poses).reshape(expected.shape), expected, atol=1e-4)


# soundfile's format and subtype, sample rate, channels, suffix, ffmpeg's encoder where soundfile has none;
# fast: the WAVs the issue named (at SR mono, 48 kHz stereo) and one file of each other codec; the rest slow
SLOW = pytest.mark.slow
FORMATS = [
    pytest.param("WAV", "PCM_16", 15360, 1, ".wav", None, id="wav16-15360-mono"),
    pytest.param("WAV", "PCM_24", 15360, 1, ".wav", None, id="wav24-15360-mono", marks=SLOW),
    pytest.param("WAV", "FLOAT", 15360, 1, ".wav", None, id="wavfloat-15360-mono", marks=SLOW),
    pytest.param("WAV", "PCM_16", 48000, 2, ".wav", None, id="wav16-48000-stereo", marks=SLOW),
    pytest.param("WAV", "PCM_24", 48000, 2, ".wav", None, id="wav24-48000-stereo", marks=SLOW),
    pytest.param("WAV", "FLOAT", 48000, 2, ".wav", None, id="wavfloat-48000-stereo"),
    pytest.param("WAV", "PCM_16", 8000, 1, ".wav", None, id="wav16-8000-mono", marks=SLOW),
    pytest.param("WAV", "PCM_24", 96000, 2, ".wav", None, id="wav24-96000-stereo", marks=SLOW),
    pytest.param("FLAC", "PCM_16", 44100, 2, ".flac", None, id="flac-44100-stereo"),
    pytest.param("MP3", "MPEG_LAYER_III", 44100, 2, ".mp3", "libmp3lame", id="mp3-44100-stereo"),
    pytest.param("OGG", "OPUS", 48000, 2, ".opus", "libopus", id="opus-48000-stereo"),
    pytest.param("OGG", "VORBIS", 22050, 1, ".ogg", "libvorbis", id="vorbis-22050-mono", marks=SLOW),
]


def write_format(path: Path, audio: np.ndarray, fmt: str, subtype: str, rate: int, channels: int,
                 encoder: str | None) -> Path:  # fmt: skip
    """``audio`` (mono at SR) resampled to ``rate``, on ``channels`` channels (the second one quieter), in
    ``fmt``/``subtype`` at ``path``: soundfile, else ffmpeg's ``encoder``; skips when neither can."""
    x = soxr.resample(audio, SR, rate) if rate != SR else audio
    x = np.stack([x, 0.5 * x], axis=1) if channels == 2 else x
    if subtype in sf.available_subtypes(fmt):
        try:
            sf.write(path, x, rate, format=fmt, subtype=subtype)
            return path
        except (sf.LibsndfileError, RuntimeError, ValueError) as err:
            reason = f"soundfile (libsndfile {sf.__libsndfile_version__}) cannot write {fmt}/{subtype}: {err}"
    else:
        reason = f"soundfile's libsndfile {sf.__libsndfile_version__} has no {fmt}/{subtype} encoder"
    ffmpeg = shutil.which("ffmpeg")
    if encoder is None or ffmpeg is None:
        pytest.skip(f"{reason}, and {'no ffmpeg on PATH' if encoder else 'no other encoder is tried'}")
    wav = path.with_suffix(".source.wav")
    sf.write(wav, x, rate, subtype="FLOAT")
    command = [ffmpeg, "-v", "error", "-y", "-i", str(wav), "-c:a", encoder, str(path)]
    proc = subprocess.run(command, capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip(f"{reason}, and ffmpeg has no working {encoder}: {proc.stderr.strip()[-200:]}")
    return path


@pytest.fixture(scope="module")
def excerpt():
    """The first FORMAT_SECONDS of music_or_synthetic, read once for all the formats."""
    return music_or_synthetic(FORMAT_SECONDS)


@pytest.fixture(scope="module")
def live_page(site, tmp_path_factory):
    """One page of the site, started, for the picks of the format tests (each pick ends the dance before)."""
    p = Page(site[0].as_uri(), tmp_path_factory.mktemp("live"))
    try:
        p.wait_for(READY, 120, "the page's start")
        yield p
    finally:
        p.close()


def answers_while(p: Page, condition: str, timeout: float, what: str) -> float:
    """Poll ``condition`` until it holds (fails after ``timeout`` s); the longest the page took to answer."""
    deadline, slowest = time.time() + timeout, 0.0
    while True:
        asked = time.time()
        held = p.js(condition)
        slowest = max(slowest, time.time() - asked)
        if held:
            return slowest
        state = p.js("JSON.stringify([smDance.status, smDance.message, smDance.frames])")
        assert time.time() < deadline, f"{what}: not in {timeout:g} s (status, message, frames: {state})"
        time.sleep(0.05)


@pytest.mark.parametrize(("fmt", "subtype", "rate", "channels", "suffix", "encoder"), FORMATS)
def test_a_picked_file_of_each_format_dances(live_page, excerpt, tmp_path, fmt, subtype, rate, channels,
                                             suffix, encoder):  # fmt: skip
    p = live_page
    name = f"{fmt}-{subtype}-{rate}-{channels}".lower()
    path = write_format(tmp_path / f"{name}{suffix}", excerpt, fmt, subtype, rate, channels, encoder)
    seen = p.js("window.smDance.statuses.length")
    p.set_file("#file", path)
    slowest = answers_while(p, f"smDance.status === 'dancing' && smDance.message.includes('{path.name}') "
                            "&& smDance.frames >= 8", 10, f"{name}: the dance's start")  # fmt: skip
    first = p.js("window.smDance.frames")
    slowest = max(slowest, answers_while(p, f"smDance.frames >= {first + 8}", 5, f"{name}: the steps"))
    poses = np.asarray(p.js("window.smDance.poses.slice(-8)"), np.float32)
    statuses = p.js(f"window.smDance.statuses.slice({seen})")
    text = p.js("document.body.innerText")
    assert p.js("window.smDance.source") == "file" and p.js("window.smDance.error") is None
    assert statuses[: statuses.index("dancing")].count("decoding") >= 1, statuses  # said while decoding
    assert np.isfinite(poses).all() and np.ptp(poses, axis=0).max() > 1e-4  # the poses change
    assert "NaN" not in text and path.name in text, text
    assert slowest < RESPONSIVE_S, f"{name}: the page took {slowest:.2f} s to answer"
    assert not p.errors, p.errors


def test_a_file_the_browser_cannot_decode_is_said_and_the_page_goes_on(live_page, excerpt, tmp_path):
    p = live_page
    bad = tmp_path / "not_music.wav"
    bad.write_bytes(b"RIFF\x00\x00\x00\x00WAVEjunk" + bytes(range(256)) * 8)
    p.set_file("#file", bad)
    slowest = answers_while(p, "smDance.status === 'error'", 10, "the refusal")
    message = p.js("window.smDance.message")
    assert 'cannot play "not_music.wav"' in message and WAITING in message, message
    on_screen = f"document.getElementById('info').textContent.includes({json.dumps(message)})"
    slowest = max(slowest, answers_while(p, on_screen, 5, "the refusal on screen"))
    assert slowest < RESPONSIVE_S and not p.errors, (slowest, p.errors)  # a warning, not an error
    good = tmp_path / "after.wav"
    sf.write(good, excerpt, SR, subtype="PCM_16")
    p.set_file("#file", good)
    answers_while(p, "smDance.status === 'dancing' && smDance.frames >= 8", 10, "the next file's dance")
    assert p.js("window.smDance.error") is None


@pytest.mark.slow
def test_a_music_file_dances_as_sm_stream_does(site, tmp_path):
    page_file, ckpt, _, wav, audio = site
    out = tmp_path / "streamed"
    assert sm(["stream", "--ckpt", str(ckpt), "--music", str(wav), "--out", str(out), "--no-render"]) == 0
    streamed = load_motion(out / f"{wav.stem}.npz")
    p = Page(page_file.as_uri(), tmp_path)
    try:
        p.wait_for(READY, 120, "the page's start")
        p.set_file("#file", wav)
        p.wait_for("window.smDance.source === 'file' && window.smDance.frames > 60", 60, "the dance")
        if os.environ.get("SM_WRITE_WEB_PNG"):
            from PIL import Image

            png = p.screenshot()[1]
            image = Image.open(io.BytesIO(png)).convert("P", palette=Image.ADAPTIVE, colors=64)
            image.thumbnail((560, 420))
            image.save(DOCS_PNG, optimize=True)
        p.wait_for("window.smDance.done", EXCERPT_S + 60, "the end of the music")
        poses = np.asarray(p.js("window.smDance.poses"), np.float32).reshape(-1, 24, 12)
        joints = np.asarray(p.js("window.smDance.joints"), np.float32).reshape(-1, 24, 3)
        latency = p.js("window.smDance.latencyMs")
        assert not p.errors, p.errors
        only_local(p.requests)
    finally:
        p.close()
    assert len(poses) == streamed.num_frames == len(audio) // HOP
    decoded = tokens_to_motion(torch.from_numpy(poses)).joints
    assert np.abs(decoded - streamed.joints).max() < JOINT_TOLERANCE_M
    assert np.abs(joints - streamed.joints).max() < JOINT_TOLERANCE_M
    assert 0 <= np.median(latency) < 1000 / 30  # each frame danced within a frame of its audio


@pytest.mark.slow
def test_the_microphone_dances(site, tmp_path):
    page_file, _, _, wav, audio = site
    flags = ("--use-fake-ui-for-media-stream", "--use-fake-device-for-media-stream",
             f"--use-file-for-fake-audio-capture={wav}")  # fmt: skip
    p = Page(page_file.as_uri(), tmp_path, flags)
    try:
        p.wait_for(READY, 120, "the page's start")
        p.js("document.getElementById('mic').click()")
        p.wait_for("window.smDance.source === 'microphone' && window.smDance.frames >= 90", 60, "the dance")
        joints = np.asarray(p.js("window.smDance.joints"), np.float32).reshape(-1, 24, 3)
        features = np.asarray(p.js("window.smDance.features"), np.float32).reshape(-1, 34)
        assert not p.errors, p.errors
        only_local(p.requests)
    finally:
        p.close()
    assert np.isfinite(joints).all() and np.abs(np.diff(joints, axis=0)).max() > 1e-3  # it moves
    # The microphone's audio is the WAV's (resampled by the browser, at an unknown offset): its loudness,
    # the log RMS feature, is the WAV's over the loudest half of the frames.
    loud = np.sort(features[:, 33])[len(features) // 2 :]
    reference = np.sort(music_features(audio, SR)[:, 33])[len(audio) // HOP // 2 :]
    assert abs(np.median(loud) - np.median(reference)) < 0.5, (np.median(loud), np.median(reference))
