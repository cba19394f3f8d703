"""A real browser with no screen: headless Chromium, driven over the DevTools protocol.

The program feed is a web page, so its tests and its delay are measured in the browser a streamer
would use (OBS's Browser Source is Chromium too). ``HeadlessChromium()`` starts the ``chromium``
of the system (Debian's package; ``tools/setup.sh`` installs it) with WebGL drawn on the CPU
(SwiftShader), and speaks the DevTools protocol over its WebSocket: open a page, wait until a
script's expression holds, take a screenshot with the page's own transparency.
"""

from __future__ import annotations

import base64
import contextlib
import io
import itertools
import json
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
from websockets.sync.client import connect

from puppet.errors import PuppetError
from puppet.show.process import end_process

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
START_TIMEOUT = 60.0
PROFILE_GRACE = 5.0  # seconds the profile folder's removal is tried again (``HeadlessChromium._remove_profile``)


class BrowserError(PuppetError, RuntimeError):
    """No browser here, or it did not start or answer."""


def find_browser() -> str | None:
    """The path of a Chromium on PATH (``BROWSERS``), or None."""
    for name in BROWSERS:
        found = shutil.which(name)
        if found:
            return found
    return None


class HeadlessChromium:
    """One headless Chromium with one page of ``size`` pixels; use it as a context manager."""

    def __init__(self, size: tuple[int, int] = (640, 640)) -> None:
        browser = find_browser()
        if browser is None:
            raise BrowserError(f"no Chromium here (looked for {', '.join(BROWSERS)}); "
                               "Debian: apt-get install chromium")
        self.size = size
        self._profile = tempfile.TemporaryDirectory(prefix="facepuppet-chromium-")
        self._process = subprocess.Popen(
            [browser, "--headless=new", "--no-sandbox", "--remote-debugging-port=0",
             f"--user-data-dir={self._profile.name}", f"--window-size={size[0]},{size[1]}",
             "--force-device-scale-factor=1", "--hide-scrollbars", "--use-angle=swiftshader",
             "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist", "--no-first-run", "--mute-audio",
             "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self._ids = itertools.count(1)
        self._closing = contextlib.ExitStack()
        try:
            self._socket = self._closing.enter_context(connect(self._page_socket(), max_size=2**26))
            self.call("Page.enable")
            self.call("Emulation.setDeviceMetricsOverride", width=size[0], height=size[1],
                      deviceScaleFactor=1, mobile=False)
            self.call("Emulation.setDefaultBackgroundColorOverride", color={"r": 0, "g": 0, "b": 0, "a": 0})
        except BaseException:
            self.close()
            raise

    def _page_socket(self) -> str:
        """The DevTools WebSocket of the browser's first page, once it is listening."""
        port_file = Path(self._profile.name) / "DevToolsActivePort"
        deadline = time.monotonic() + START_TIMEOUT
        while time.monotonic() < deadline:
            if self._process.poll() is not None:
                raise BrowserError(f"chromium exited at start (status {self._process.returncode})")
            if port_file.is_file() and port_file.read_text().strip():
                port = port_file.read_text().split()[0]
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=5) as answer:
                    pages = [p for p in json.load(answer) if p.get("type") == "page"]
                if pages:
                    return pages[0]["webSocketDebuggerUrl"]
            time.sleep(0.1)
        raise BrowserError(f"chromium did not open its DevTools port within {START_TIMEOUT} s")

    def call(self, method: str, **params: Any) -> dict:
        """One DevTools command; its result (BrowserError with the browser's message on error)."""
        ident = next(self._ids)
        self._socket.send(json.dumps({"id": ident, "method": method, "params": params}))
        while True:
            answer = json.loads(self._socket.recv(timeout=START_TIMEOUT))
            if answer.get("id") == ident:
                if "error" in answer:
                    raise BrowserError(f"{method}: {answer['error'].get('message')}")
                return answer.get("result", {})

    def open(self, url: str) -> None:
        self.call("Page.navigate", url=url)

    def evaluate(self, expression: str) -> Any:
        """A JavaScript expression's value in the page (JSON-able values)."""
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in result:
            raise BrowserError(f"{expression}: {result['exceptionDetails'].get('text')}")
        return result["result"].get("value")

    def wait_for(self, expression: str, timeout: float = 60.0) -> Any:
        """Wait until ``expression`` is truthy in the page; its value (BrowserError on timeout)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = self.evaluate(expression)
            if value:
                return value
            time.sleep(0.05)
        raise BrowserError(f"the page did not reach {expression!r} within {timeout} s")

    def screenshot(self) -> np.ndarray:
        """The page as (height, width, 4) uint8 RGBA, alpha 0 where it is transparent."""
        from PIL import Image

        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))

    def close(self) -> None:
        self._closing.close()
        end_process(self._process, 10)
        self._remove_profile()

    def _remove_profile(self) -> None:
        """Remove the browser's profile folder. Chromium's helper processes can still write into it
        for a moment after the browser has ended, and a removal that met a new file failed ("Directory
        not empty"): it is tried again for up to ``PROFILE_GRACE`` seconds, then what is left stays in
        the system's temporary folder."""
        deadline = time.monotonic() + PROFILE_GRACE
        while True:
            try:
                self._profile.cleanup()
                return
            except OSError:
                if time.monotonic() > deadline:
                    shutil.rmtree(self._profile.name, ignore_errors=True)
                    return
                time.sleep(0.1)

    def __enter__(self) -> HeadlessChromium:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
