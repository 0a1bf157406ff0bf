"""A viewer page in a real headless Chromium, driven over the Chrome DevTools Protocol (websocket-client:
a few kilobytes of pure Python talking to the system browser, where Playwright would bring its own driver
and browser builds). Tests call :func:`browser_or_skip` first: it skips without Chromium or the client."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import subprocess
import time
import urllib.request
from pathlib import Path
from urllib.parse import urlparse

import numpy as np
import pytest

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.stream.ort_web import read_ort_web

BROWSER = next((b for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)


def browser_or_skip() -> str:
    """The Chromium executable; skips the calling test when it or the CDP client is missing."""
    pytest.importorskip("websocket", reason="websocket-client (pip) drives Chromium over CDP")
    pytest.importorskip("PIL.Image", reason="Pillow decodes the screenshots")
    if BROWSER is None:
        pytest.skip("no Chromium on PATH (apt-get install chromium; .ci/run installs it where apt works)")
    return BROWSER


class PageCrashed(AssertionError):
    """The page's renderer died (crashed, or Chromium terminated it): nothing it would answer comes."""


class NoDocument(AssertionError):
    """No document to evaluate in yet: the page is between documents (a cross-origin isolated page loads in
    a new renderer process; a page of tens of megabytes takes seconds to arrive)."""


class Page:
    """A page of a headless Chromium; ``flags``: more command-line switches. ``errors`` collects console
    errors and exceptions, ``requests`` the URL of every request the page made. A call raises
    :class:`PageCrashed` at once when the renderer dies (else it would wait out the socket's 60 s)."""

    def __init__(self, url: str, tmp: Path, flags: tuple[str, ...] = ()):
        import websocket

        self.proc = subprocess.Popen(
            [
                browser_or_skip(),
                "--headless=new",
                "--no-sandbox",
                "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader",
                "--autoplay-policy=no-user-gesture-required",
                "--remote-debugging-port=0",
                f"--user-data-dir={tmp / 'profile'}",
                "--window-size=800,600",
                *flags,
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
        self.next_id, self.errors, self.requests = 0, [], []
        self.call("Inspector.enable")
        self.call("Runtime.enable")
        self.call("Log.enable")
        self.call("Network.enable")

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
            elif message.get("method") == "Network.requestWillBeSent":
                self.requests.append(message["params"]["request"]["url"])
            elif message.get("method") == "Inspector.targetCrashed":
                raise PageCrashed(f"the page's renderer died during {method} ({self.errors})")
            if message.get("id") == self.next_id:
                if "Cannot find default execution context" in message.get("error", {}).get("message", ""):
                    raise NoDocument(message)
                assert "error" not in message, message
                return message["result"]

    def js(self, expression: str):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        assert "exceptionDetails" not in result, result
        return result["result"].get("value")

    def screenshot(self) -> np.ndarray:
        from PIL import Image

        png = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")), png

    def close(self):
        self.ws.close()
        self.proc.kill()
        self.proc.wait()

    def open(self, url: str, timeout: float = 60.0) -> None:
        """Load ``url`` in this page and wait until the viewer has set ``window.smViewer``."""
        self.js("window.smViewer = undefined")
        self.call("Page.navigate", url=url)
        self.wait_for_viewer(timeout)

    def wait_for_viewer(self, timeout: float = 60.0) -> None:
        started = "typeof window.smViewer === 'object' && window.smViewer !== null"
        self.wait_for(started, timeout, "the viewer's start")

    def wait_for(self, expression: str, timeout: float = 60.0, what: str | None = None) -> None:
        """Poll until the JavaScript ``expression`` is truthy (fails after ``timeout`` seconds)."""
        deadline = time.time() + timeout
        while True:
            try:
                if self.js(expression):
                    return
            except NoDocument:  # not yet loaded: as not yet true
                pass
            assert time.time() < deadline, f"{what or expression}: not in {timeout:g} s ({self.errors})"
            time.sleep(0.1)

    def set_file(self, selector: str, path: Path) -> None:
        """Choose ``path`` in the file input at ``selector`` (as a user would: its change event fires).

        The path goes to Chromium absolute: given a relative one, Chromium grants the page that path but
        the renderer asks for the file by its absolute name, and the browser terminates the renderer about
        a second later ("Terminating renderer for bad IPC message, reason 2" on its stderr), which looks
        like a page that stopped answering."""
        path = Path(path).resolve()
        assert path.is_file(), f"{path}: no such file to pick"
        root = self.call("DOM.getDocument")["root"]["nodeId"]
        node = self.call("DOM.querySelector", nodeId=root, selector=selector)["nodeId"]
        self.call("DOM.setFileInputFiles", files=[str(path)], nodeId=node)


READY = "!!(window.smDance && window.smDance.ready)"


def ort_web_or_skip() -> None:
    try:
        read_ort_web()
    except InputError as err:
        pytest.skip(f"onnxruntime-web not available: {err}")


def only_local(requests: list[str]) -> None:
    schemes = {urlparse(url).scheme for url in requests}
    assert schemes <= {"file", "data"}, requests
