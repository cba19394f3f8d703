"""The player: real-time frame selection, pause / step / Home / looping, random access to the
frames of a take in bounded memory, and a clear message where no window can open. No test opens
a window on a display; one draws through a headless (offscreen) moderngl-window window."""

from __future__ import annotations

import sys
import types
import warnings

import numpy as np
import pytest
from window_keys import WindowKeys as _Keys

from puppet import cli
from puppet.face.load import load_face
from puppet.io.fapfile import FapWarning, write_fap
from puppet.runtime.runtime import Runtime
from puppet.view import window as player
from puppet.view.demo import demo_take
from puppet.view.rendertake import FapPlayback
from puppet.view.window import HeldTable, NoDisplayError, PlayClock, check_display, window_title

LINUX_LIKE = sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd"))


# -- PlayClock ----------------------------------------------------------------------------


def test_the_frame_follows_the_wall_clock_at_the_takes_fps():
    clock = PlayClock(25, 100, now=10.0)
    assert [clock.frame(10.0 + t) for t in (0.0, 0.039, 0.04, 0.5, 1.0, 3.99)] == [0, 0, 1, 12, 25, 99]
    assert clock.frame(14.0) == 0 and clock.frame(14.04) == 1  # loops after the last frame
    assert clock.position(12.0) == pytest.approx(50.0)


def test_playback_never_runs_faster_than_the_fps_and_drops_frames_when_slow():
    clock = PlayClock(30, 1000)
    dense = [clock.frame(t) for t in np.arange(0.0, 2.0, 0.001)]  # a loop far faster than 30 Hz
    assert len(set(dense)) == 60 and dense == sorted(dense)
    slow = [clock.frame(t) for t in np.arange(0.0, 2.0, 0.1)]  # drawing at 10 Hz
    assert slow[:4] == [0, 3, 6, 9] and slow[-1] == 57


def test_next_change_is_when_the_next_frame_is_due():
    clock = PlayClock(25, 100, now=0.0)
    due = clock.next_change(0.013)
    assert due == pytest.approx(0.04)
    assert clock.frame(due) == 1 and clock.frame(np.nextafter(due, 0) - 1e-6) == 0
    clock.pause(0.5)
    assert clock.next_change(0.6) is None


def test_pause_holds_the_frame_and_resume_carries_on_without_a_jump():
    clock = PlayClock(25, 1000)
    clock.pause(1.01)
    assert clock.paused and clock.frame(1.01) == clock.frame(50.0) == 25
    clock.resume(50.0)
    assert not clock.paused
    assert clock.frame(50.0) == 25 and clock.frame(50.0 + 0.04) == 26  # paused time not counted
    clock.toggle(51.0)
    assert clock.paused and clock.frame(60.0) == 50
    clock.toggle(60.0)
    assert not clock.paused and clock.frame(61.0) == 75


def test_stepping_pauses_and_moves_one_frame_wrapping_at_the_ends():
    clock = PlayClock(25, 10)
    assert clock.step(0.2, 1) == 6 and clock.paused
    assert clock.frame(5.0) == 6
    assert clock.step(5.0, -1) == 5 and clock.step(5.0, -1) == 4
    clock.seek(5.0, 9)
    assert clock.step(6.0, 1) == 0  # past the last frame: the first
    assert clock.step(6.0, -1) == 9  # before the first: the last
    clock.resume(7.0)
    assert clock.frame(7.04) == 0  # plays on from the stepped frame


def test_home_goes_to_frame_zero_keeping_play_or_pause():
    clock = PlayClock(25, 100)
    clock.home(2.0)
    assert clock.frame(2.0) == 0 and clock.frame(2.2) == 5
    clock.pause(2.2)
    clock.home(3.0)
    assert clock.paused and clock.frame(9.0) == 0


def test_without_looping_it_stops_on_the_last_frame_and_a_resume_starts_over():
    clock = PlayClock(10, 20, loop=False)
    assert clock.frame(1.95) == 19 and not clock.at_end(1.85)
    assert clock.frame(100.0) == 19 and clock.at_end(100.0)
    assert clock.next_change(100.0) is None
    assert clock.step(100.0, 1) == 19 and clock.step(100.0, -30) == 0  # clamps
    clock.seek(100.0, 19)
    clock.toggle(100.5)  # play on the last frame starts over
    assert not clock.paused and clock.frame(100.5) == 0 and clock.frame(100.65) == 1
    clock.toggle(100.65)
    assert clock.paused and clock.frame(101.0) == 1


def test_an_unknown_length_counts_up_until_it_is_known():
    clock = PlayClock(25)
    assert clock.frame(400.0) == 10000
    assert clock.step(0.0, -1) == 0 and clock.paused  # nothing to wrap to yet
    clock.n_frames = 98
    assert clock.step(0.0, -1) == 97
    clock.resume(0.0)
    assert clock.frame(0.04) == 0


def test_a_clock_needs_a_positive_fps_and_a_frame():
    with pytest.raises(ValueError):
        PlayClock(0)
    with pytest.raises(ValueError):
        PlayClock(25, 0)


def test_the_title_shows_file_frame_total_fps_and_pause():
    assert window_title("take.fap", 11, 98, 25.0, False) == "take.fap | frame 12/98 | 25 fps"
    assert window_title("t.fap", 0, None, 29.97, True) == "t.fap | frame 1/? | 29.97 fps | paused"


# -- HeldTable: random access in bounded memory --------------------------------------------


@pytest.fixture(scope="module")
def runtime():
    return Runtime(load_face())


def _take(path, frames=12, fps=25, declared=None):
    """A take whose FAPs change only in some frames, so that later frames rely on held values."""
    values = np.zeros((frames, 68))
    mask = np.zeros((frames, 68), dtype=bool)
    for k in range(frames):
        if k % 3 == 0:
            values[k, 2] = 25 * k  # open_jaw, sent every third frame only
            mask[k, 2] = True
        values[k, 48] = 1500 * np.sin(k)  # head yaw, every frame
        mask[k, 48] = True
    values[5, 18] = 500  # a blink, held from frame 5 on
    mask[5, 18] = True
    write_fap(path, (values, mask), fps=fps)
    if declared is not None:
        lines = path.read_text().splitlines(keepends=True)
        lines[0] = f"2.1 take {fps} {declared}\n"
        path.write_text("".join(lines))
    return path


def test_any_frame_deforms_as_streaming_playback_does(tmp_path, runtime):
    path = _take(tmp_path / "take.fap")
    streamed = [v.copy() for v, _ in FapPlayback(path, runtime.face, runtime)]
    table = HeldTable(path, runtime, declared_frames=12)
    for k in (7, 2, 11, 0, 5, 4, 11, 6):  # out of order, backwards included
        vertices, normals = table.mesh(k)
        assert np.allclose(vertices, streamed[k], atol=1e-5), k
        assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-3)
        alone, none = table.mesh(k, normals=False)  # for a renderer that sums normals in its draw
        assert none is None and np.array_equal(alone, vertices)
    assert not np.allclose(streamed[4], streamed[5], atol=1e-4)  # the frames do differ
    with pytest.raises(IndexError):
        table.mesh(12)


def test_the_table_reads_lazily_and_holds_68_float32_per_frame(tmp_path, runtime):
    path = _take(tmp_path / "take.fap", frames=40)
    table = HeldTable(path, runtime, declared_frames=40)
    assert table.ensure(3) and table.count == 3 and not table.complete
    assert table.total == 40  # the header's word, until the end is reached
    table.read_ahead(deadline=float("inf"))
    assert table.complete and table.count == table.total == 40
    assert not table.ensure(41)
    assert table.low_level(39).dtype == np.float32 and table.low_level(39).shape == (68,)
    assert table.nbytes == HeldTable.CHUNK * 68 * 4  # 272 B a frame: 24 MB for an hour at 25 fps
    assert table.low_level(6)[18] == 500  # FAP 19, sent in frame 5, held


def test_a_take_cut_short_plays_the_frames_it_has(tmp_path, runtime):
    path = _take(tmp_path / "short.fap", frames=6, declared=10)
    table = HeldTable(path, runtime, declared_frames=10)
    with pytest.warns(FapWarning, match="declares 10 frames"):
        assert not table.ensure(8)
    assert table.complete and table.total == table.count == 6


def test_a_malformed_frame_ends_the_take_with_a_warning(tmp_path, runtime):
    path = _take(tmp_path / "bad.fap", frames=8)
    lines = path.read_text().splitlines(keepends=True)
    lines[1 + 2 * 5 + 1] = "5 oops\n"  # the value line of frame 5
    path.write_text("".join(lines))
    table = HeldTable(path, runtime)
    with pytest.warns(FapWarning, match="playing the 5 frames before it"):
        table.read_ahead(deadline=float("inf"))
    assert table.complete and table.count == 5


# -- no display --------------------------------------------------------------------------


def test_check_display_wants_x11_or_wayland_on_linux():
    with pytest.raises(NoDisplayError, match="DISPLAY is not set"):
        check_display({}, "linux")
    check_display({"DISPLAY": ":0"}, "linux")
    check_display({"WAYLAND_DISPLAY": "wayland-0"}, "linux")
    check_display({}, "darwin")
    check_display({}, "win32")


@pytest.mark.skipif(not LINUX_LIKE, reason="a display is an X11 / Wayland matter")
def test_play_without_a_display_says_so_and_exits_2(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(SystemExit) as exit_:
        cli.main(["play", str(demo_take())])
    assert exit_.value.code == 2
    assert capsys.readouterr().err.strip() == (
        "puppet play: no display to open a window on (DISPLAY is not set);"
        " use 'puppet render TAKE -o take.mp4' instead")


@pytest.mark.skipif(not LINUX_LIKE, reason="a display is an X11 / Wayland matter")
def test_play_on_a_display_that_does_not_answer_exits_2(monkeypatch, capsys):
    monkeypatch.setenv("DISPLAY", ":4242")
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setenv("MODERNGL_WINDOW", "pyglet")
    with pytest.raises(SystemExit) as exit_:
        player.play_take(demo_take())
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("puppet play: ") and "puppet render" in err and "Traceback" not in err


# -- the player's loop, drawing offscreen ----------------------------------------------------


class _FakeTime:
    def __init__(self) -> None:
        self.now = 100.0

    def perf_counter(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds



def test_the_player_draws_frames_and_obeys_the_keys(tmp_path, runtime, monkeypatch, headless_window):
    clock = _FakeTime()
    monkeypatch.setattr(player, "time", types.SimpleNamespace(perf_counter=clock.perf_counter,
                                                               sleep=clock.sleep))
    path = _take(tmp_path / "take.fap", frames=12, fps=10)
    window = headless_window((96, 72), _Keys)
    playback = FapPlayback(path, runtime.face, runtime)
    play = player.Player(playback, window)

    def press(key):
        play._on_key(key, _Keys.ACTION_PRESS, None)

    press(_Keys.H)  # the status line hidden: the face alone is compared (its own test is below)

    def shown():
        play._update()
        pixels = np.frombuffer(window.fbo.read(components=3), dtype=np.uint8)
        return play._shown, pixels.reshape(72, 96, 3).astype(int)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FapWarning)
        play.clock.seek(clock.now, 0)
        first, image0 = shown()
        assert first == 0 and np.ptp(image0[36]) > 60  # a face across the middle row
        assert window.title == "take.fap | frame 1/12 | 10 fps"
        play._idle()  # reads the rest of the take ahead while waiting for the next frame
        assert play.table.complete and 100.0 < clock.now <= 100.1  # woken by the next frame
        clock.now = 100.0
        clock.now += 0.35
        assert shown()[0] == 3
        press(_Keys.SPACE)
        clock.now += 5.0
        assert shown()[0] == 3 and window.title.endswith("| paused")
        press(_Keys.RIGHT)
        k, image4 = shown()
        assert k == 4 and np.abs(image4 - image0).max() > 30
        press(_Keys.LEFT)
        press(_Keys.LEFT)
        assert shown()[0] == 2
        press(_Keys.HOME)
        k, image = shown()
        assert k == 0 and np.array_equal(image, image0)
        press(_Keys.LEFT)
        assert shown()[0] == 11 and play.clock.n_frames == 12  # wraps to the last frame
        press(_Keys.SPACE)
        clock.now += 0.1
        assert shown()[0] == 0  # and plays on, looping
        press(_Keys.Q)
        assert play._quit
        play.run()  # returns at once, releasing the renderer and the window
    assert play.renderer is None and play.table.complete


def test_the_status_line_says_frame_time_length_fps_and_pause():
    from puppet.view.playbar import play_status

    assert play_status(11, 98, 25.0, False) == "frame 12/98   0:00.44 / 0:03.92   25 fps   playing"
    assert play_status(1499, None, 25.0, True) == "frame 1500/?   0:59.96 / ?   25 fps   paused"


def test_the_window_itself_shows_frame_time_and_pause_and_h_hides_it(tmp_path, runtime, monkeypatch,
                                                                       headless_window):
    """Many window managers show no title: the frame, the time and "paused" are drawn in the
    window (bottom left), redrawn when only the pause changes, and H hides them."""
    clock = _FakeTime()
    monkeypatch.setattr(player, "time", types.SimpleNamespace(perf_counter=clock.perf_counter,
                                                               sleep=clock.sleep))
    size = (480, 360)
    window = headless_window(size, _Keys)
    play = player.Player(FapPlayback(_take(tmp_path / "take.fap", frames=12, fps=10), runtime.face, runtime),
                         window)
    corner = (slice(size[1] - 40, size[1] - 4), slice(4, size[0] - 4))  # the status line, bottom left

    def drawn():
        play._update()
        pixels = np.frombuffer(window.fbo.read(components=3), dtype=np.uint8).reshape(size[1], size[0], 3)
        return pixels[::-1][corner].astype(int)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FapWarning)
        play.clock.seek(clock.now, 0)
        playing = drawn()
        assert play._bar_shown == ("frame 1/12   0:00.00 / 0:01.20   10 fps   playing", True)
        play._on_key(_Keys.SPACE, _Keys.ACTION_PRESS, None)
        paused = drawn()  # the same frame, only paused: drawn again all the same
        assert play._bar_shown[0].endswith("paused") and np.abs(paused - playing).max() > 60
        play._on_key(_Keys.H, _Keys.ACTION_PRESS, None)
        hidden = drawn()
        assert np.abs(paused - hidden).mean() > 10 and np.abs(playing - hidden).mean() > 10  # even the first
    play._on_key(_Keys.Q, _Keys.ACTION_PRESS, None)
    play.run()
