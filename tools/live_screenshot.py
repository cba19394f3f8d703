"""A screenshot of the live window, cockpit and channel monitor shown, as a user sees it.

    xvfb-run -s "-screen 0 1280x800x24" .venv/bin/python tools/live_screenshot.py docs/live_cockpit.png

Opens the real window (``puppet.view.window.open_window``: pyglet; under Xvfb when there is no
screen), performs the shipped slider-box mapping with the simulated box for a second, turns the
channel monitor on and saves the window's pixels.
"""

from __future__ import annotations

import sys
import tempfile
import time

import numpy as np
from PIL import Image

from puppet.io.shipped import shipped_mappings
from puppet.view.livewindow import LiveView, open_session
from puppet.view.window import open_window

SIM_BOX = {"box": "sim://joystick?protocol=ascii&rate=200&channels=6"}


def main(out: str, size: tuple[int, int] = (960, 720), seconds: float = 1.5) -> None:
    window = open_window("arduino_sliders", size)
    with tempfile.TemporaryDirectory() as takes:
        session = open_session(shipped_mappings()["arduino_sliders"], devices=SIM_BOX, record_root=takes)
        live = LiveView(session, window)
        try:
            live.cockpit.monitor = True
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                live.step()
            frame = session.frame()  # drawn once more, read before the swap
            live.renderer.draw(frame.vertices, frame.normals, framebuffer=window.fbo)
            live._draw_cockpit(frame.states)
            width, height = window.buffer_size
            pixels = np.frombuffer(window.fbo.read(components=3), dtype=np.uint8).reshape(height, width, 3)
            Image.fromarray(pixels[::-1]).save(out, optimize=True)
        finally:
            live.close()
            session.close()
    print(out)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "docs/live_cockpit.png")
