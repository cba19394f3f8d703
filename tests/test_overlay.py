"""The live window's cockpit: drawn in the window over the face (headless here), it shows the
status and the channel monitor, and hidden it draws nothing."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from puppet.live import LiveView, open_session
from puppet.overlay import device_lines
from puppet.shipped import shipped_mappings

SIM_BOX = {"box": "sim://joystick?protocol=ascii&rate=200&channels=6"}
SIZE = (960, 720)


class _Keys:
    ACTION_PRESS, ACTION_RELEASE = "press", "release"
    R, N, C, K, M, H, Q, ESCAPE = "r", "n", "c", "k", "m", "h", "q", "escape"
    TAB, LEFT, RIGHT, UP, DOWN, PAGE_UP, PAGE_DOWN = "tab", "left", "right", "up", "down", "pgup", "pgdn"
    HOME, END, DELETE, SPACE, BACKSPACE, ENTER = "home", "end", "delete", "space", "backspace", "enter"


def _pixels(window) -> np.ndarray:
    return np.frombuffer(window.fbo.read(components=3), dtype=np.uint8).reshape(SIZE[1], SIZE[0], 3)[::-1]


def _steps(live: LiveView, n: int) -> None:
    for _ in range(n):
        time.sleep(0.01)
        live.step()


def test_the_cockpit_draws_over_the_face_and_hidden_draws_nothing(tmp_path, headless_window):
    window = headless_window(SIZE, _Keys)
    session = open_session(shipped_mappings()["arduino_sliders"], devices=SIM_BOX, record_root=tmp_path)
    live = LiveView(session, window)
    try:
        _steps(live, 3)
        shown = _pixels(window)
        imgui = live.cockpit.imgui
        drawn = imgui.get_frame_count()
        live._on_key(_Keys.H, _Keys.ACTION_PRESS, None)
        _steps(live, 3)
        hidden = _pixels(window)
        assert imgui.get_frame_count() == drawn  # hidden: not one ImGui frame
        corner = (slice(10, 150), slice(10, 200))    # the status panel, top left
        assert np.abs(shown[corner].astype(int) - hidden[corner].astype(int)).mean() > 10

        live._on_key(_Keys.H, _Keys.ACTION_PRESS, None)
        live._on_key(_Keys.M, _Keys.ACTION_PRESS, None)
        _steps(live, 3)
        monitor = _pixels(window)
        right = (slice(10, 150), slice(SIZE[0] - 300, SIZE[0] - 10))  # the channel monitor, top right
        assert np.abs(monitor[right].astype(int) - hidden[right].astype(int)).mean() > 10
    finally:
        live.close()
        session.close()


def test_a_lost_device_shows_why():
    class Counters:
        last_error = "[Errno 2] could not open port /dev/ttyACM0"

    class Device:
        counters = Counters()

    states = {"box": type("S", (), {"value": "lost"})(), "pad": type("S", (), {"value": "open"})()}
    lines = device_lines(states, {"box": Device(), "pad": Device()})
    assert [(d.name, d.state, d.reason) for d in lines] == [
        ("box", "lost", "[Errno 2] could not open port /dev/ttyACM0"), ("pad", "open", "")]


def test_a_screenshot_of_the_real_window_under_xvfb_shows_the_cockpit(tmp_path):
    if shutil.which("xvfb-run") is None:
        pytest.skip("no xvfb-run here (tools/setup.sh installs xvfb where it can)")
    root = Path(__file__).resolve().parents[1]
    shot = tmp_path / "live.png"
    subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x800x24", sys.executable, str(root / "tools" / "live_screenshot.py"),
                    str(shot)], check=True, cwd=root, env={**os.environ, "PYTHONPATH": str(root)},
                   capture_output=True, timeout=120)
    pixels = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert pixels.shape == (720, 960, 3)
    panel, monitor = pixels[10:190, 10:300], pixels[10:170, 530:950]
    assert panel.std() > 20 and monitor.std() > 20  # text and graphs, not an empty backdrop


def test_calibration_from_the_window_guides_rest_then_sweep_and_writes_the_mapping(tmp_path, headless_window):
    from puppet.calibrate import GuidedCalibration
    from puppet.mapping import load_mapping

    mapping = tmp_path / "sliders.yaml"
    mapping.write_bytes(shipped_mappings()["arduino_sliders"].read_bytes())
    window = headless_window(SIZE, _Keys)
    start = time.monotonic()  # the box's clock starts with the session: 3 s at rest, then sweeps
    session = open_session(mapping, devices={"box": SIM_BOX["box"] + "&motion=calibrate&rest=3"},
                           record_root=tmp_path)
    live = LiveView(session, window)
    try:
        live._on_key(_Keys.K, _Keys.ACTION_PRESS, None)
        calibration = live.calibration
        assert isinstance(calibration, GuidedCalibration)
        now = time.monotonic()
        assert now < start + 2.4, "the window took too long to open: the box stopped resting"
        ends = (now + 0.1, now + 0.6, max(now + 0.7, start + 3.2), start + 4.4)  # sweeping from start + 3
        calibration._ends = [(phase, end) for (phase, _), end in zip(calibration._ends, ends)]
        seen = set()
        while live.calibration is not None:
            live.step()
            seen.add(calibration.phase()[0])
            assert time.monotonic() - start < 10
        assert {"rest", "sweep"} <= seen and "calibrated" in live.notice
        assert (tmp_path / "sliders.yaml.bak").exists()
        assert mapping.read_bytes() != (tmp_path / "sliders.yaml.bak").read_bytes()
        load_mapping(mapping)
        assert session.mapping.file == str(mapping)
    finally:
        live.close()
        session.close()


@pytest.mark.parametrize("case", ["shipped", "recording"])
def test_the_window_does_not_calibrate_a_shipped_mapping_or_while_recording(tmp_path, headless_window, case):
    mapping = shipped_mappings()["arduino_sliders"]
    if case == "recording":
        mapping = tmp_path / "mine.yaml"
        mapping.write_bytes(shipped_mappings()["arduino_sliders"].read_bytes())
    window = headless_window(SIZE, _Keys)
    session = open_session(mapping, devices=SIM_BOX, record_root=tmp_path)
    live = LiveView(session, window)
    try:
        if case == "recording":
            live._on_key(_Keys.R, _Keys.ACTION_PRESS, None)
        live._on_key(_Keys.K, _Keys.ACTION_PRESS, None)
        assert live.calibration is None
        assert ("shipped mapping" if case == "shipped" else "stop recording first") in live.notice
    finally:
        live.close()
        session.close()
