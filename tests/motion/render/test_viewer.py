"""The viewer page in a real headless Chromium, driven over the Chrome DevTools Protocol
(:mod:`browser_page`). Checks: no console error or exception; the canvas is not blank; screenshots at two
times differ; after seeking to t the rendered root projects to where the motion file puts it and the
pixel there is the body's colour; the audio element's clock follows the scrub."""

from __future__ import annotations

import io
import os
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from skeleton_mamba.tasks.motion.formats.gltf import from_motion_data
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.motion.render.view import write_view
from tests.helpers.browser_page import Page, browser_or_skip

DOCS = Path(__file__).resolve().parents[3] / "docs" / "viewer.png"


def _dance(frames: int = 90) -> MotionData:
    """A body walking along +x (1 m/s) and waving: the root moves, so do the limbs."""
    t = np.arange(frames) / 30.0
    poses = np.zeros((frames, 24, 3), np.float32)
    poses[:, 16, 2] = -1.2 + 0.8 * np.sin(2 * np.pi * t)  # left shoulder
    poses[:, 17, 2] = 1.2 - 0.8 * np.sin(2 * np.pi * t)
    poses[:, 1, 0] = 0.5 * np.sin(2 * np.pi * t)  # hips
    poses[:, 2, 0] = -0.5 * np.sin(2 * np.pi * t)
    trans = np.stack([t - 1.5, 0.95 + 0.0 * t, 0.0 * t], axis=1).astype(np.float32)
    return MotionData(30.0, poses=poses, trans=trans)


@pytest.fixture
def page(tmp_path):
    browser_or_skip()
    motion = _dance()
    wav = tmp_path / "music.wav"
    sf.write(wav, 0.1 * np.sin(2 * np.pi * 440 * np.arange(3 * 8000) / 8000), 8000)
    out = write_view(
        [("generated", from_motion_data(motion)), ("reference", from_motion_data(_dance()))],
        tmp_path / "view.html",
        music=wav,
        metrics={"FID_k": 31.4, "BeatAlign": 0.24},
    )
    p = Page(out.as_uri(), tmp_path)
    p.wait_for_viewer()
    yield p, motion, out
    p.close()


def test_viewer_in_chromium(page):
    p, motion, out = page
    assert p.js("window.smViewer.duration") == pytest.approx((motion.num_frames - 1) / motion.fps, abs=1e-4)
    p.js(
        "document.getElementById('music').readyState >= 1 || new Promise(r => "
        "document.getElementById('music').addEventListener('loadedmetadata', r))"
    )
    shots = {}
    for t in (0.5, 2.0):
        p.js(f"window.smViewer.seek({t}); window.smViewer.render()")
        image, png = p.screenshot()
        shots[t] = image
        assert image.reshape(-1, 3).std(axis=0).max() > 5, "the canvas is blank"
        # The root of motion 0 at time t from the file (frame t * fps), shifted as the page places it.
        frame = round(t * motion.fps)
        expected = motion.root_position()[frame] + np.asarray(p.js("window.smViewer.offset(0)"))
        rendered = p.js("window.smViewer.project(window.smViewer.rootWorld(0))")
        from_file = p.js(f"window.smViewer.project({expected.tolist()})")
        assert np.hypot(*np.subtract(rendered, from_file)) < 2.0
        x, y = (int(round(v)) for v in from_file)
        patch = image[y - 3 : y + 4, x - 3 : x + 4].reshape(-1, 3).astype(int)
        assert np.any(patch[:, 0] > patch[:, 2] + 60), f"no body colour at the root's pixel {x, y}"
        assert p.js("document.getElementById('music').currentTime") == pytest.approx(t, abs=0.05)
        if t == 2.0 and os.environ.get("SM_WRITE_VIEWER_PNG"):
            from PIL import Image

            small = Image.open(io.BytesIO(png)).convert("P", palette=Image.ADAPTIVE, colors=64)
            small.thumbnail((560, 420))
            small.save(DOCS, optimize=True)
    differ = np.abs(shots[0.5].astype(int) - shots[2.0].astype(int)).max(axis=2) > 30
    assert differ.sum() > 200, "the body did not move between the two screenshots"
    p.js("window.smViewer.play()")
    time.sleep(0.5)
    assert p.js("window.smViewer.time()") > 0
    assert not p.errors, p.errors
    assert out.stat().st_size < 3_000_000
