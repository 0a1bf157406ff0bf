"""The viewer page in a real headless Chromium, driven over the Chrome DevTools Protocol (websocket-client:
a few kilobytes of pure Python talking to the system browser, where Playwright would bring its own driver
and browser builds). Checks: no console error or exception; the canvas is not blank; screenshots at two
times differ; after seeking to t the rendered root projects to where the motion file puts it and the
pixel there is the body's colour; the audio element's clock follows the scrub."""

from __future__ import annotations

import base64
import io
import json
import os
import re
import shutil
import subprocess
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from skeleton_mamba.tasks.motion.gltf import from_motion_data
from skeleton_mamba.tasks.motion.motion_file import MotionData
from skeleton_mamba.tasks.motion.view import write_view

websocket = pytest.importorskip("websocket", reason="websocket-client (pip) drives Chromium over CDP")
PIL = pytest.importorskip("PIL.Image", reason="Pillow decodes the screenshots")
BROWSER = next((b for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)
DOCS = Path(__file__).resolve().parents[1] / "docs" / "viewer.png"


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


class Page:
    def __init__(self, url: str, tmp: Path):
        self.proc = subprocess.Popen(
            [
                BROWSER,
                "--headless=new",
                "--no-sandbox",
                "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader",
                "--autoplay-policy=no-user-gesture-required",
                "--remote-debugging-port=0",
                f"--user-data-dir={tmp / 'profile'}",
                "--window-size=800,600",
                url,
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        port = None
        deadline = time.time() + 60
        while port is None and time.time() < deadline:
            line = self.proc.stderr.readline()
            match = re.search(r"DevTools listening on ws://[^:]+:(\d+)/", line)
            port = match and int(match.group(1))
        assert port, "Chromium did not open its DevTools port"
        for _ in range(100):
            targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list"))
            pages = [t for t in targets if t["type"] == "page"]
            if pages:
                break
            time.sleep(0.1)
        self.ws = websocket.create_connection(
            pages[0]["webSocketDebuggerUrl"], timeout=60, suppress_origin=True
        )
        self.next_id, self.errors = 0, []
        self.call("Runtime.enable")
        self.call("Log.enable")

    def call(self, method: str, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            message = json.loads(self.ws.recv())
            if message.get("method") == "Runtime.exceptionThrown":
                self.errors.append(message["params"]["exceptionDetails"])
            elif message.get("method") == "Runtime.consoleAPICalled" and message["params"]["type"] == "error":
                self.errors.append(message["params"]["args"])
            elif message.get("method") == "Log.entryAdded" and message["params"]["entry"]["level"] == "error":
                self.errors.append(message["params"]["entry"])
            if message.get("id") == self.next_id:
                assert "error" not in message, message
                return message["result"]

    def js(self, expression: str):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        assert "exceptionDetails" not in result, result
        return result["result"].get("value")

    def screenshot(self) -> np.ndarray:
        png = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return np.asarray(PIL.open(io.BytesIO(png)).convert("RGB")), png

    def close(self):
        self.ws.close()
        self.proc.kill()
        self.proc.wait()


@pytest.fixture
def page(tmp_path):
    if BROWSER is None:
        pytest.skip("no Chromium on PATH (apt-get install chromium; .ci/run installs it where apt works)")
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
    deadline = time.time() + 60
    while not p.js("typeof window.smViewer === 'object'") and time.time() < deadline:
        time.sleep(0.2)
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
            small = PIL.open(io.BytesIO(png)).convert("P", palette=PIL.ADAPTIVE, colors=64)
            small.thumbnail((560, 420))
            small.save(DOCS, optimize=True)
    differ = np.abs(shots[0.5].astype(int) - shots[2.0].astype(int)).max(axis=2) > 30
    assert differ.sum() > 200, "the body did not move between the two screenshots"
    p.js("window.smViewer.play()")
    time.sleep(0.5)
    assert p.js("window.smViewer.time()") > 0
    assert not p.errors, p.errors
    assert out.stat().st_size < 3_000_000
