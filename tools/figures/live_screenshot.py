"""A screenshot of the live window with everything its cockpit shows, as a user sees it.

    xvfb-run -s "-screen 0 1280x800x24" .venv/bin/python tools/figures/live_screenshot.py docs/guide/live_cockpit.png

Opens the real window (``puppet.view.window.open_window``: pyglet; under Xvfb when there is no
screen) on the shipped slider-box mapping with a second device added, a foot pedal on a serial
port that is not there, so the cockpit shows a LOST device and why. The simulated box performs
for a few seconds (the fps and latency graphs fill), a take is recording, the channel monitor is
on; then the window's pixels are saved. tests/test_overlay.py runs it under Xvfb and checks
that the picture, and the one in the guide, shows each part.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from PIL import Image

from puppet.io.shipped import shipped_mappings
from puppet.view.livewindow import LiveView, open_session
from puppet.view.window import open_window

SIM_BOX = {"box": "sim://joystick?protocol=ascii&rate=200&channels=6"}
PEDAL = "serial:///dev/ttyUSB7?baudrate=115200"
"""The pedal's port: absent, so the cockpit shows it LOST with the reason (port missing)."""


def mapping_with_a_missing_pedal(folder: Path) -> Path:
    """The shipped slider box mapping plus a pedal device (one channel) that is not plugged in."""
    mapping = yaml.safe_load(shipped_mappings()["arduino_sliders"].read_text("utf-8"))
    mapping["devices"]["pedal"] = {"url": PEDAL, "options": {"protocol": "ascii"}}
    mapping["channels"]["pedal.ch0"] = {"min": 0, "max": 1023}
    mapping["targets"].append({"fap": "raise_b_midlip", "source": "pedal.ch0", "range": [0, 200]})
    path = folder / "sliders_and_pedal.yaml"
    path.write_text(yaml.safe_dump(mapping, sort_keys=False), encoding="utf-8")
    return path


def _ready(session, elapsed: float, seconds: float) -> bool:
    """After ``seconds`` (the graphs fill), once every channel of the box has read something (its
    bars show), however slow the machine; a minute at the most."""
    box = [c for c in session.mapping.channels() if c.name.startswith("box.")]
    return elapsed >= 60 or (elapsed >= seconds and all(c.raw is not None for c in box))


def main(out: str, size: tuple[int, int] = (960, 720), seconds: float = 3.0) -> None:
    with tempfile.TemporaryDirectory() as folder:
        window = open_window("arduino_sliders", size)
        session = open_session(mapping_with_a_missing_pedal(Path(folder)), devices=SIM_BOX, record_root=folder)
        live = LiveView(session, window)
        try:
            live.cockpit.monitor = True
            start = time.monotonic()
            while not _ready(session, time.monotonic() - start, seconds):
                if live.take is None and time.monotonic() > start + seconds / 2:
                    live._on_key(window.keys.R, window.keys.ACTION_PRESS, None)  # REC from half way
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
    main(sys.argv[1] if len(sys.argv) > 1 else "docs/guide/live_cockpit.png")
