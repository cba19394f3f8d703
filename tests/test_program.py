"""The program window (``puppet program``, ``--program``): the feed read back and drawn on a key colour
into a headless window, pixel for pixel against the transparent render; its refusals; and the
window's process started and ended with the rig."""

from __future__ import annotations

import contextlib
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from puppet import cli
from puppet.show.program import FeedFace, ProgramError, ProgramProcess, ProgramWindow, feed_url, open_feed
from puppet.show.server import ShowServer
from puppet.view.renderer import Renderer, aim_camera
from puppet.view.rendertake import head_points

LINUX_LIKE = sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd"))
MAPPING = Path(__file__).resolve().parents[1] / "mappings" / "arduino_sliders.yaml"
SIZE = (160, 160)


@pytest.fixture
def server(face):
    camera = aim_camera(head_points(face), SIZE)
    with ShowServer(face, camera, port=0, size=SIZE) as started:
        started.publish(face.vertices)
        yield started


@pytest.fixture
def program(headless_window):
    """Makes the program window of a server's feed, drawing into a headless window."""
    with contextlib.ExitStack() as stack:
        def make(server, key=(0, 255, 0), size=SIZE):
            feed, feed_face = stack.enter_context(open_feed(server.page_url))
            return ProgramWindow(feed, feed_face, headless_window(size), key)

        yield make


def _shown(program) -> np.ndarray:
    assert program.step(5.0)
    width, height = program.window.buffer_size
    pixels = np.frombuffer(program.window.fbo.read(components=3), dtype=np.uint8)
    return pixels.reshape(height, width, 3)[::-1]


def _transparent(face, feed_face: FeedFace, vertices: np.ndarray, size=SIZE) -> np.ndarray:
    with Renderer(face.triangles, len(face.vertices), face.colors, width=size[0], height=size[1],
                  transparent=True) as renderer:
        renderer.camera = feed_face.camera
        return renderer.render(vertices)


@pytest.mark.parametrize("key", [(0, 255, 0), (0x12, 0x34, 0x56)])
def test_the_face_is_the_transparent_render_and_the_rest_is_exactly_the_key(server, face, program, key):
    window = program(server, key)
    shown = _shown(window)
    reference = _transparent(face, window.frames.face, window.vertices)
    alpha = reference[..., 3]
    face_pixels, background = alpha == 255, alpha == 0
    assert 0.15 < face_pixels.mean() < 0.8 and background.mean() > 0.15
    assert np.array_equal(shown[face_pixels], reference[face_pixels][:, :3])
    assert np.all(shown[background] == key)
    assert np.abs(window.vertices - face.vertices).max() < 1e-4 * np.ptp(face.vertices)


def test_an_open_mouth_published_opens_the_mouth_in_the_window(server, face, runtime, program):
    window = program(server)
    rest = _shown(window).astype(int)
    opened = runtime.deform_faps({"open_jaw": 600.0})
    server.publish(opened)
    shown = _shown(window).astype(int)
    changed = np.abs(shown - rest).max(axis=2) > 8
    moved = np.linalg.norm(opened - face.vertices, axis=1) > 1e-3 * np.ptp(face.vertices)
    with Renderer(face.triangles, len(face.vertices), width=SIZE[0], height=SIZE[1]) as renderer:
        renderer.camera = window.frames.face.camera
        columns, rows = renderer.project(opened[moved]).T
    rows_changed, columns_changed = np.nonzero(changed)
    assert changed.sum() > 100
    assert rows_changed.min() >= rows.min() - 2 and columns_changed.min() >= columns.min() - 2  # only where the
    assert rows_changed.max() <= rows.max() + 2 and columns_changed.max() <= columns.max() + 2  # jaw moved
    assert rows.min() > SIZE[1] * 0.4  # and that is the lower face


def test_each_frame_drawn_is_echoed_and_the_window_ends_with_the_feed(face, program):
    camera = aim_camera(head_points(face), SIZE)
    server = ShowServer(face, camera, port=0, size=SIZE).start()
    try:
        server.publish(face.vertices)
        window = program(server, size=(120, 90))
        assert _shown(window).shape == (90, 120, 3)  # a window of another shape is drawn at its own size
        deadline = time.monotonic() + 5
        while not server.delays_ms and time.monotonic() < deadline:
            time.sleep(0.02)
        assert len(server.delays_ms) == 1 and server.viewers == 1
    finally:
        server.close()
    assert window.run() == "feed ended"


def test_a_feed_that_is_not_there_or_refuses_says_why(server):
    with pytest.raises(ProgramError, match="not a program feed URL"):
        feed_url("http://127.0.0.1:8765/")
    assert feed_url("http://127.0.0.1:8765/?token=abc") == "ws://127.0.0.1:8765/feed?token=abc"
    wrong = server.page_url.split("token=")[0] + "token=wrong"
    with pytest.raises(ProgramError, match=r"refused the feed \(HTTP 403\): use the URL"):
        open_feed(wrong).__enter__()
    with pytest.raises(ProgramError, match="cannot reach the feed at 127.0.0.1:9: .*is `puppet live --serve` running"):
        open_feed("http://127.0.0.1:9/?token=abc").__enter__()


@pytest.mark.skipif(not LINUX_LIKE, reason="a display is an X11 / Wayland matter")
@pytest.mark.parametrize("argv, line", [
    (["program", "http://127.0.0.1:8765/?token=abc"],
     "puppet program: no display to open a window on (DISPLAY is not set)"),
    (["live", "--mapping", str(MAPPING), "--serve", "127.0.0.1:0", "--no-window", "--program"],
     "puppet live: --program: no display to open a window on (DISPLAY is not set)"),
    (["live", "--mapping", str(MAPPING), "--program"],
     "puppet live: --program needs --serve HOST:PORT: the window shows the served feed"),
    (["play", "take.fap", "--program"],
     "puppet play: --program needs --serve HOST:PORT: the window shows the served feed"),
])
def test_without_a_display_or_a_feed_it_says_so_in_one_line_and_exits_2(monkeypatch, capsys, argv, line):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert cli.main(argv) == 2
    assert capsys.readouterr().err.strip() == line


def test_a_key_colour_is_six_hex_digits(capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["program", "http://127.0.0.1:8765/?token=abc", "--key-colour", "green"])
    assert exit_.value.code == 2
    assert "expected a colour as RRGGBB in hex such as 00FF00, got 'green'" in capsys.readouterr().err


@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="needs Xvfb, a virtual X display, to open a real window")
def test_the_rigs_program_window_opens_on_a_display_and_closes_with_the_rig(server, face, monkeypatch):
    display = ":" + str(90 + (server.port % 50))
    xvfb = subprocess.Popen(["Xvfb", display, "-screen", "0", "800x800x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(0.5)
        monkeypatch.setenv("DISPLAY", display)
        window = ProgramProcess(server, (0, 255, 0), (200, 200))
        deadline = time.monotonic() + 60
        while server.viewers == 0 and window.process.poll() is None and time.monotonic() < deadline:
            server.publish(face.vertices)
            time.sleep(0.1)
        assert server.viewers == 1, f"the window's process ended with {window.process.poll()}"
        window.close()
        assert window.process.returncode is not None
        deadline = time.monotonic() + 5
        while server.viewers and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.viewers == 0
    finally:
        xvfb.terminate()
        xvfb.wait(5)

