"""``sm export-web``'s page in a real headless Chromium, driven over CDP (:mod:`browser_page`).

Fast: the page opens from disk, makes no request but its own file (and the data URLs inside it), logs
no error, and onnxruntime-web's wasm steps give the poses that onnxruntime in Python gives for the same
audio. Slow (``-m slow``): a music file picked in the page dances as it plays, and its poses, read back,
equal ``sm stream``'s on the same WAV within 1 mm; the microphone (Chromium's fake device playing the WAV)
dances too. ``SM_WRITE_WEB_PNG=CKPT`` exports CKPT (e.g. the stream demo's) for the file test and writes
the screenshot mid-dance to ``docs/web_dancer.png``.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from urllib.parse import urlparse

import numpy as np
import pytest
import soundfile as sf
import torch
from browser_page import Page, browser_or_skip
from checkpoint_files import tiny_stream_checkpoint
from conftest import SHARED_DATA

from skeleton_mamba.tasks.motion.errors import InputError
from skeleton_mamba.tasks.motion.motion_file import load_motion
from skeleton_mamba.tasks.motion.music import load_audio
from skeleton_mamba.tasks.motion.synthetic import synthesize_music
from skeleton_mamba.tasks.stream.features import HOP, SR, music_features
from skeleton_mamba.tasks.stream.model import tokens_to_motion
from skeleton_mamba.tasks.stream.ort_web import read_ort_web
from skeleton_mamba.tasks.stream.web_export import export_web_graph
from skeleton_mamba.tasks.stream.web_graph import run_web_graph
from skeleton_mamba.tasks.training.cli import main as sm

DOCS_PNG = Path(__file__).resolve().parents[1] / "docs" / "web_dancer.png"
EXCERPT_S = 8.0  # of a sample track, danced in real time by the slow tests
JOINT_TOLERANCE_M = 1e-3
READY = "!!(window.smDance && window.smDance.ready)"


def ort_web_or_skip() -> None:
    try:
        read_ort_web()
    except InputError as err:
        pytest.skip(f"onnxruntime-web not available: {err}")


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


def only_local(requests: list[str]) -> None:
    schemes = {urlparse(url).scheme for url in requests}
    assert schemes <= {"file", "data"}, requests


def test_page_opens_from_disk_and_steps_like_onnxruntime(site, tmp_path):
    page_file, ckpt, dancer, _, audio = site
    if dancer is None:
        pytest.skip("SM_WRITE_WEB_PNG is set: the page holds that checkpoint (the slow test uses it)")
    p = Page(page_file.as_uri(), tmp_path)
    try:
        p.wait_for(READY, 120, "the page's start")
        frames = 45
        samples = audio[: frames * HOP].tolist()
        poses = p.js(
            f"(async () => {{ const x = {samples}; for (let t = 0; t < {frames}; t++) "
            f"await window.smDance.step(x.slice(t * {HOP}, (t + 1) * {HOP})); "
            "return window.smDance.poses; })()"
        )
        assert p.js("window.smDance.threads") == 1  # from disk: not cross-origin isolated
        assert not p.errors, p.errors
        only_local(p.requests)
    finally:
        p.close()
    graph = tmp_path / "dancer.onnx"
    export_web_graph(dancer, graph)
    expected = run_web_graph(graph, dancer, audio[: frames * HOP])["pose"]
    np.testing.assert_allclose(np.asarray(poses).reshape(expected.shape), expected, atol=1e-4)


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
