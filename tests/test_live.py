"""``puppet live``: the no-display exit, the title / stats / monitor helpers, and the live loop
drawn into a headless (offscreen) moderngl-window window with a simulated slider box."""

from __future__ import annotations

import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest
from window_keys import WindowKeys as _Keys

from puppet import cli
from puppet.io.fapfile import iter_fap
from puppet.io.takes import open_take
from puppet.view.livewindow import LiveStats, LiveView, live_title, open_session

LINUX_LIKE = sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd"))
MAPPING = Path(__file__).resolve().parents[1] / "mappings" / "arduino_sliders.yaml"
SIM_BOX = {"box": "sim://joystick?protocol=ascii&rate=200&channels=6"}


@pytest.mark.skipif(not LINUX_LIKE, reason="a display is an X11 / Wayland matter")
def test_live_without_a_display_says_so_and_exits_2(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(SystemExit) as exit_:
        cli.main(["live", "--mapping", str(MAPPING), "--record", "x", "--fps", "25"])
    assert exit_.value.code == 2
    assert capsys.readouterr().err.strip() == (
        "puppet live: no display to open a window on (DISPLAY is not set)")


def test_stats_fps_and_median_latency_over_the_last_second():
    stats = LiveStats()
    assert stats.latency_ms is None
    for k in range(30):  # 30 frames in 0.5 s, latencies 1..3 ms, only frames with new samples
        t = 10**9 + k * 16_666_667
        stats.drawn(t, t - (1 + k % 3) * 10**6, new_samples=True)
        stats.drawn(t + 1, t - 50 * 10**6, new_samples=False)
    assert stats.fps == 60 and stats.latency_ms == pytest.approx(2.0)
    stats.drawn(10**10, None, new_samples=False)  # much later: the old ones drop out
    assert stats.fps == 1 and stats.latency_ms is None


def test_title():
    state = types.SimpleNamespace(name="OPEN")
    assert live_title("sliders", 59.6, 12.34, {"box": state}, "take_001") == (
        "sliders | 60 fps | 12.3 ms | box: open | REC take_001")
    assert live_title("sliders", 0, None, {}, None) == "sliders | 0 fps | -- ms"


# -- the loop, drawing offscreen --------------------------------------------------------------


def test_the_live_loop_draws_records_and_obeys_the_keys(tmp_path, headless_window):
    window = headless_window((96, 72))
    session = open_session(MAPPING, record="run", fps=30, devices=SIM_BOX, record_root=tmp_path)
    live = LiveView(session, window)

    def press(key):
        live._on_key(key, _Keys.ACTION_PRESS, None)

    def frames(n):
        for _ in range(n):
            time.sleep(0.02)
            live.step()

    try:
        frames(5)
        pixels = np.frombuffer(window.fbo.read(components=3), dtype=np.uint8).reshape(72, 96, 3)
        assert np.ptp(pixels[36].astype(int)) > 60  # a face across the middle row
        assert window.title.startswith("arduino_sliders | ") and "box: open" in window.title
        assert " ms" in window.title and "REC" not in window.title
        assert live.stats.latency_ms is not None  # the sim box streams at 200 Hz

        press(_Keys.R)
        assert session.recording
        frames(5)
        assert window.title.endswith("| REC run_001")
        press(_Keys.R)
        assert not session.recording and live.takes == [tmp_path / "run_001"]
        frames(1)
        assert "REC" not in window.title
        take = live.takes[0]
        with iter_fap(take / "take.fap") as reader:
            assert sum(1 for _ in reader) >= 2  # ~0.1 s at 30 fps
        assert (take / "take.json").exists() and (take / "samples.jsonl").stat().st_size > 0

        press(_Keys.M)
        frames(1)
        assert live.cockpit.monitor
        press(_Keys.M)

        press(_Keys.R)  # Q finishes a take that is running
        press(_Keys.N)  # neutral: channels back to rest, noted in the take
        frames(2)
        press(_Keys.C)  # re-centre the bipolar sliders (brows) where they are
        frames(1)
        press(_Keys.Q)
        assert live._quit and not session.recording
        assert live.takes[-1] == tmp_path / "run_002"
        events = [e for e in open_take(live.takes[-1]).entries() if hasattr(e, "kind")]
        assert any(e.kind == "reset" for e in events)
        assert any(e.kind == "recentre" and set(e.data["centres"]) == {"box.ch3", "box.ch4"} for e in events)
        live.run()  # returns at once, releasing the renderer and the window
        assert live.renderer is None
    finally:
        session.close()


def test_device_overrides_are_parsed_from_the_command_line():
    import argparse

    from puppet.cli import _device_override

    assert _device_override("box=sim://joystick?rate=200") == ("box", "sim://joystick?rate=200")
    with pytest.raises(argparse.ArgumentTypeError, match="NAME=URL"):
        _device_override("box")


def test_a_device_name_the_mapping_does_not_use_is_refused_naming_the_ones_it_has(capsys):
    assert cli.main(["live", "--mapping", "arduino_sliders", "--device", "pad=sim://joystick"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("puppet live: ")
    assert "no device named 'pad'" in err and "this mapping's devices: box" in err
