"""The live window's cockpit: drawn in the window over the face (headless here), it shows the
status and the channel monitor, and hidden it draws nothing."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from window_keys import WindowKeys as _Keys

from puppet.io.shipped import shipped_mappings
from puppet.view.livewindow import LiveView, open_session
from puppet.view.overlay import device_lines

SIM_BOX = {"box": "sim://joystick?protocol=ascii&rate=200&channels=6"}
SIZE = (960, 720)


def _pixels(window) -> np.ndarray:
    return np.frombuffer(window.fbo.read(components=3), dtype=np.uint8).reshape(SIZE[1], SIZE[0], 3)[::-1]


def _steps(live: LiveView, n: int) -> None:
    for _ in range(n):
        time.sleep(0.01)
        live.step()


def test_the_cockpit_draws_over_the_face_and_hidden_draws_nothing(tmp_path, headless_window):
    window = headless_window(SIZE)
    session = open_session(shipped_mappings()["arduino_sliders"], devices=SIM_BOX, record_root=tmp_path)
    live = LiveView(session, window)
    try:
        _steps(live, 3)
        shown = _pixels(window)
        imgui = live.cockpit.imgui
        drawn = imgui.get_frame_count()
        live._on_key(_Keys.M, _Keys.ACTION_PRESS, None)
        live._on_key(_Keys.H, _Keys.ACTION_PRESS, None)
        reads = []
        channels = session.mapping.channels
        session.mapping.channels = lambda: reads.append(1) or channels()
        _steps(live, 3)
        hidden = _pixels(window)
        assert imgui.get_frame_count() == drawn  # hidden: not one ImGui frame
        assert reads == [] and len(live.cockpit.fps) == 6  # nor a channel read; the graphs still fill
        session.mapping.channels = channels
        live._on_key(_Keys.M, _Keys.ACTION_PRESS, None)
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


def test_a_lost_device_shows_why_and_one_never_there_is_unavailable_not_lost():
    from devices.base import Counters

    class Device:
        def __init__(self, counters: Counters) -> None:
            self.counters = counters

    unplugged = Counters(samples=120, reconnects=1, last_error="[Errno 2] could not open port /dev/ttyACM0")
    never = Counters(last_error="no MIDI system (no /dev/snd/seq: load the ALSA sequencer, sudo modprobe snd-seq)")
    lost, opened = type("S", (), {"value": "lost"})(), type("S", (), {"value": "open"})()
    lines = device_lines({"box": lost, "pad": opened, "faders": lost},
                         {"box": Device(unplugged), "pad": Device(Counters(samples=5)), "faders": Device(never)})
    assert [(d.name, d.state, d.reason) for d in lines] == [
        ("box", "lost", "[Errno 2] could not open port /dev/ttyACM0"), ("pad", "open", ""),
        ("faders", "unavailable", never.last_error)]


def _cockpit_parts(pixels: np.ndarray) -> set[str]:
    """Which of the cockpit's parts a 960x720 screenshot shows, by their colours where the
    cockpit puts them: the status panel top left, the channel monitor top right."""
    def shows(region: np.ndarray, rgb: tuple[int, int, int], least: int = 30) -> bool:
        return int((np.abs(region - np.array(rgb)).max(axis=2) < 40).sum()) >= least

    status, monitor = pixels[:330, :300], pixels[:230, 520:]
    parts = {name for name, rgb in (("device open", (102, 255, 102)), ("device lost", (255, 115, 89)),
                                    ("REC", (255, 51, 51))) if shows(status, rgb)}
    if status.std() > 20:
        parts.add("text and graphs")
    def runs(rgb: tuple[int, int, int]) -> int:  # runs of rows with that colour in them
        rows = (np.abs(monitor - np.array(rgb)).max(axis=2) < 12).any(axis=1)
        return int(np.count_nonzero(np.diff(rows.astype(int)) == 1))

    # a bar per channel row (its frame shows at any value) and values filling some of them
    if runs((43, 61, 88)) >= 6 and runs((230, 179, 0)) >= 3:
        parts.add("channel bars")
    return parts


EVERYTHING = {"device open", "device lost", "REC", "text and graphs", "channel bars"}


@pytest.mark.slow
def test_a_screenshot_of_the_real_window_under_xvfb_shows_everything_and_so_does_the_one_in_docs(tmp_path):
    """tools/figures/live_screenshot.py under Xvfb (the real pyglet window): the status with a device open
    and one LOST with its reason, REC, the graphs and keys, the channel monitor's bars; and the
    picture in docs/ that the same tool took shows them all too."""
    root = Path(__file__).resolve().parents[1]
    docs = np.asarray(Image.open(root / "docs" / "guide" / "live_cockpit.png").convert("RGB")).astype(int)
    assert docs.shape == (720, 960, 3) and _cockpit_parts(docs) == EVERYTHING
    if shutil.which("xvfb-run") is None:
        pytest.skip("no xvfb-run here (tools/setup.sh installs xvfb where it can)")
    shot = tmp_path / "live.png"
    tool = root / "tools" / "figures" / "live_screenshot.py"
    subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x800x24", sys.executable, str(tool), str(shot)],
                   check=True, cwd=root, env={**os.environ, "PYTHONPATH": str(root)}, capture_output=True, timeout=120)
    pixels = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert pixels.shape == (720, 960, 3) and _cockpit_parts(pixels) == EVERYTHING
    face = pixels[300:600, 380:580]
    assert face.std() > 20  # the face under it


def _calibrating_box(tmp_path: Path, window, rest: float):
    """(mapping, session, view): a copy of the slider box mapping, live on the simulated box's
    calibration motion (hands off for ``rest`` s, then sweeping)."""
    mapping = tmp_path / "sliders.yaml"
    mapping.write_bytes(shipped_mappings()["arduino_sliders"].read_bytes())
    box = {"box": f"sim://joystick?protocol=ascii&rate=200&channels=6&motion=calibrate&rest={rest:g}"}
    session = open_session(mapping, devices=box, record_root=tmp_path)
    return mapping, session, LiveView(session, window)


@pytest.mark.slow
def test_calibration_from_the_window_guides_rest_then_sweep_and_writes_the_mapping(tmp_path, headless_window):
    """K, against the simulated box's calibration motion (hands off for its first 6 s, then
    sweeping). The phases are moved on here by what the box does rather than by the clock (rest:
    5 frames; get ready: until the box sweeps; sweep: 3 s and 10 frames), so a slow machine
    calibrates the same."""
    from puppet.live.calibrate import GuidedCalibration
    from puppet.live.mappingfile import load_mapping

    mapping, session, live = _calibrating_box(tmp_path, headless_window(SIZE), rest=6)
    try:
        live._on_key(_Keys.K, _Keys.ACTION_PRESS, None)
        calibration = live.calibration
        assert isinstance(calibration, GuidedCalibration)
        start = time.monotonic()
        ends = {"ready": start, "rest": start + 1e6, "get ready to sweep": start + 2e6, "sweep": start + 3e6}
        frames = dict.fromkeys(ends, 0)
        swept_from = None
        while live.calibration is not None:
            calibration._ends = list(ends.items())
            live.step()
            phase, now = calibration.phase()[0], time.monotonic()
            frames[phase] = frames.get(phase, 0) + 1
            raws = [c.raw for c in session.mapping.channels() if c.raw is not None]
            if phase == "rest" and frames["rest"] >= 5:
                ends["rest"] = now
            elif phase == "get ready to sweep" and any(abs(r - 512) > 200 for r in raws):
                ends["get ready to sweep"], swept_from = now, now
            elif phase == "sweep" and now - swept_from >= 3 and frames["sweep"] >= 10:
                ends["sweep"] = now
            assert now - start < 60
        assert frames["rest"] >= 5 and frames["sweep"] >= 10 and "calibrated 6 of 6" in live.notice
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
    window = headless_window(SIZE)
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


def test_an_audio_input_shows_its_level_against_its_gate_and_its_xruns(tmp_path, headless_window, capsys):
    """A microphone (here a wav:// file at real-time pace) gets a level meter in the cockpit, green
    above its gate; its overruns and underruns are counted beside it. A take recorded with it
    is said to be saved with its length, frames and sound."""
    from puppet.io.wavwriter import WavWriter

    wav = tmp_path / "ah.wav"
    with WavWriter(wav, 48000) as writer:
        writer.write((8000 * np.sin(2 * np.pi * 220 * np.arange(96000) / 48000)).astype(np.int16))
    window = headless_window(SIZE)
    session = open_session(shipped_mappings()["arduino_sliders_voice"],
                           devices={**SIM_BOX, "mic": f"wav://{wav}?loop=1"}, record_root=tmp_path)
    live = LiveView(session, window)
    try:
        _steps(live, 30)
        [mic] = [line for line in device_lines(session.states, session.devices) if line.name == "mic"]
        assert mic.state == "open" and mic.level_db > mic.gate_db and 0.5 < mic.meter < 1.0
        assert (mic.overruns, mic.underruns) == (session.devices["mic"].counters.overruns,
                                                 session.devices["mic"].counters.underruns)
        live._on_key(_Keys.R, _Keys.ACTION_PRESS, None)
        _steps(live, 20)
        live._on_key(_Keys.R, _Keys.ACTION_PRESS, None)
        saved = [line for line in capsys.readouterr().err.splitlines() if line.startswith("take saved: ")]
        assert len(saved) == 1 and re.search(r"\(\d+\.\d s, \d+ frames at 30 fps, \d+ readings, with its sound\)$",
                                             saved[0]), saved
        pixels = _pixels(window)
        panel = pixels[8:300, 8:330].reshape(-1, 3).astype(int)
        bar = np.all(np.abs(panel - (76, 217, 89)) < 12, axis=1)  # the meter's green, not the text's
        assert bar.sum() > 300
    finally:
        live.close()
        session.close()
    box = device_lines(session.states, session.devices)[0]
    assert box.level_db is None  # a slider box has no meter


def test_the_channel_monitor_says_how_many_more_targets_a_channel_drives():
    from puppet.view.overlay import targets_label

    assert targets_label(("open_jaw",)) == "open_jaw"
    assert targets_label(("raise_l_cornerlip", "stretch_l_cornerlip")) == "raise_l_cornerlip and 1 more target"
    assert targets_label(tuple(f"t{k}" for k in range(6))) == "t0 and 5 more targets"


def test_a_layered_pass_shows_its_base_take_in_the_cockpit(tmp_path, headless_window):
    from puppet.view.demo import demo_take

    window = headless_window(SIZE)
    session = open_session(shipped_mappings()["arduino_sliders"], devices=SIM_BOX, record_root=tmp_path,
                           layer_over=demo_take(), arm=["box.ch0"])
    live = LiveView(session, window)
    try:
        _steps(live, 3)
        said = session.layer_status()
        assert said.startswith("over demo_take.fap, frame 1 of 98 (0:00.00 of 0:03.92); armed: open_jaw")
        panel = _pixels(window)[8:320, 8:400].reshape(-1, 3).astype(int)
        assert np.all(np.abs(panel - (140, 204, 255)) < 40, axis=1).sum() > 30  # the layer line's blue
    finally:
        live.close()
        session.close()


@pytest.mark.slow
def test_k_starts_the_simulated_hand_over_however_long_the_window_took_to_open(tmp_path, headless_window):
    """The guide's simulated box (motion=calibrate, rest=4) rests for 4 s after it opens, then
    sweeps; a window that took longer than that to open would calibrate a sweep as the rest.
    K tells the simulated hand to start over: it rests again while the cockpit says to."""
    _, session, live = _calibrating_box(tmp_path, headless_window(SIZE), rest=4)

    def away_from_rest() -> float:
        return max(abs(c.raw - 512) for c in session.mapping.channels() if c.raw is not None)

    try:
        start = time.monotonic()
        while time.monotonic() - start < 5.0:  # the window "opening": the box's rest is over
            live.step()
        assert away_from_rest() > 100
        live._on_key(_Keys.K, _Keys.ACTION_PRESS, None)
        _steps(live, 30)
        assert live.calibration.phase()[0] == "ready" and away_from_rest() < 40  # at rest again
    finally:
        live.close()
        session.close()


def test_a_take_saved_with_no_window_is_said_with_its_length_and_frames(tmp_path, capsys):
    """``puppet live --no-window``: a take stopped by the control API is said as the window says it."""
    from puppet.view.liveoutput import HeadlessLive
    from puppet.view.livewindow import LiveStats

    session = open_session(shipped_mappings()["arduino_sliders"], devices=SIM_BOX, record_root=tmp_path)
    live = HeadlessLive(session, [], LiveStats())
    try:
        session.start_recording()
        for _ in range(10):
            live.step()
            time.sleep(0.02)
        session.stop_recording()
        live.step()
    finally:
        session.close()
    saved = [line for line in capsys.readouterr().err.splitlines() if line.startswith("take saved: ")]
    assert len(saved) == 1 and re.search(r"take_001 \(\d+\.\d s, \d+ frames at 30 fps, \d+ readings\)$", saved[0])


def test_a_calibration_that_leaves_channels_as_they_were_says_so_in_red_in_the_cockpit(tmp_path, headless_window):
    """Nobody sweeps (the simulated hand rests all along): every channel is left as it was, and the
    cockpit says so in red for FAILURE_S, not only the terminal."""
    from puppet.view.livewindow import FAILURE_S

    mapping, session, live = _calibrating_box(tmp_path, headless_window(SIZE), rest=600)
    before = mapping.read_bytes()
    try:
        live._on_key(_Keys.K, _Keys.ACTION_PRESS, None)
        calibration, start = live.calibration, time.monotonic()
        frames = dict.fromkeys(("ready", "rest", "get ready to sweep", "sweep"), 0)
        while live.calibration is not None:  # each phase moved on after 5 frames, however slow they are
            now = time.monotonic()
            calibration._ends = [(phase, now - 1 if n >= 5 else now + 1e6) for phase, n in frames.items()]
            live.step()
            phase = calibration.phase()[0]
            frames[phase] = frames.get(phase, 0) + 1
            assert now - start < 60
        _steps(live, 2)
        assert live.notice.startswith("calibrated 0 of 6 channels") and live.notice_failed
        assert live._notice_until - time.monotonic() > FAILURE_S - 5
        panel = _pixels(window=live.window)[8:400, 8:600].reshape(-1, 3).astype(int)
        assert np.all(np.abs(panel - (255, 77, 77)) < 12, axis=1).sum() > 30  # the notice's red
        assert mapping.read_bytes() == before
    finally:
        live.close()
        session.close()
