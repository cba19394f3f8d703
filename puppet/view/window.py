"""Playing a .fap take in a window, in real time: ``puppet play TAKE``.

``play_take`` opens a moderngl-window window (the pyglet backend; glfw if pyglet cannot open one
and the ``glfw`` package is installed) and draws the take with ``render.Renderer`` straight into
the window's framebuffer.

Keys: space pauses and resumes; right / left arrow step one frame forward / back (and pause);
Home goes to the first frame (keeping play or pause); H hides the status line; Q or Escape closes
the window. The title shows the file name, the frame (counted from 1) of the total, the take's fps
and "paused"; the window itself says the same and the time, at the bottom left (``playbar``), for
window managers that show no title.

Decisions
---------
* **Timing** (``PlayClock``, pure, no window): the frame shown at wall-clock time ``t`` is
  ``floor(position)``, where the position advances by ``fps`` frames per second of playing. So
  playback never runs faster than the take's fps, and when drawing is slower, frames are dropped
  rather than the take slowing down. The window loop sleeps until the next frame is due
  (waking at least every ``IDLE_WAKE`` to handle keys) and draws only when something changed.
* **End of the take: it loops**, back to frame 0, like a turntable review of a motion. Stepping
  back from frame 0 goes to the last frame once the take's length is known.
* **Random access in bounded memory** (``HeldTable``): ``FapPlayback`` streams forward only, and a
  FAP frame transmits only its masked FAPs, so frame *k* depends on every frame before it. The
  player therefore keeps, per frame, the *held* state already expanded to the 68 low-level FAPs
  (``HeldFaps.low_level``), as float32: 272 bytes a frame, 24 MB for an hour at 25 fps. Any frame
  is then deformed on demand (FAPs -> controls -> ``Runtime.deform_with_normals``, as
  ``FapPlayback`` does), so stepping back or to Home is instant and no vertices are cached. The
  table is filled lazily while reading the file forward (about 0.1 ms a frame): the frames about
  to be shown first, then the rest of the file in the idle time between frames, so the window
  opens at once even on an hour-long take and the total becomes exact when the end is reached
  (until then the title shows the header's declared count, or "?").
* **A malformed frame** part way through the file ends the take there, with a ``FapWarning``: the
  frames before it play.
* **No display**: on Linux and the BSDs, without ``DISPLAY`` or ``WAYLAND_DISPLAY``, no window can
  be opened; ``open_window`` raises ``NoDisplayError`` (and ``WindowError`` for any other failure
  to open a GL 3.3 window), and ``play_take`` turns either into a one-line message on stderr,
  pointing at ``puppet render``, and ``SystemExit(2)``.
"""

from __future__ import annotations

import math
import os
import sys
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from puppet.errors import PuppetError
from puppet.face.model import Face
from puppet.fap.held import held_low_level
from puppet.fap.pose import Pose
from puppet.fap.table import N_FAPS
from puppet.io.fapfile import FapError, FapReader, FapWarning, iter_fap
from puppet.io.soundtrack import soundtrack
from puppet.runtime.runtime import Runtime
from puppet.view.liveoutput import LiveOutput, close_outputs
from puppet.view.playbar import PlayBar, play_status
from puppet.view.renderer import Renderer, software_rasteriser
from puppet.view.rendertake import VIEWS, FapPlayback, aim_at_head
from puppet.view.soundout import ClockedSound

BACKENDS = ("pyglet", "glfw")
"""moderngl-window backends tried in order (glfw only where its package is installed)."""

IDLE_WAKE = 1.0 / 60.0
"""Longest sleep of the window loop, in seconds: how late a key press may be handled (twice
that where the backend can only handle events by swapping buffers, i.e. by drawing)."""

RENDER_HINT = "use 'puppet render TAKE -o take.mp4' instead"


class WindowError(PuppetError, RuntimeError):
    """No window could be opened (no display, no OpenGL 3.3, no window backend)."""


class NoDisplayError(WindowError):
    """There is no display to open a window on."""


# -- timing -------------------------------------------------------------------------------


class PlayClock:
    """Which frame to show at a wall-clock time: real-time play, pause, steps, seeks, looping.

    Times are seconds on any monotonic clock (``time.perf_counter`` in the window); every method
    takes the current time ``now`` rather than reading a clock, so tests drive it directly.
    ``n_frames`` None means the length is not known yet: frames then count up without wrapping
    (set it when the end of the take is found). With ``loop`` the take wraps to frame 0 after
    its last frame; without, it stays on the last frame (``at_end``) until resumed, which starts
    over.
    """

    def __init__(self, fps: float, n_frames: int | None = None, *, loop: bool = True,
                 now: float = 0.0, paused: bool = False) -> None:
        if not 0.0 < fps < math.inf:
            raise ValueError(f"fps must be positive, got {fps}")
        self.fps = float(fps)
        self.loop = loop
        self.n_frames = n_frames
        self._paused = paused
        self._origin = 0.0   # position (in frames) at _anchor
        self._anchor = now

    @property
    def n_frames(self) -> int | None:
        return self._n_frames

    @n_frames.setter
    def n_frames(self, value: int | None) -> None:
        if value is not None and value < 1:
            raise ValueError(f"a take to play needs at least 1 frame, got {value}")
        self._n_frames = value

    @property
    def paused(self) -> bool:
        return self._paused

    def position(self, now: float) -> float:
        """The playhead in frames, unwrapped: it grows past the end when looping."""
        if self._paused:
            return self._origin
        return self._origin + (now - self._anchor) * self.fps

    def seconds(self, now: float) -> float | None:
        """Where playback is in the take at ``now``, in seconds (wrapped when looping); None
        while it stands still (paused, or held on the last frame): what its sound follows."""
        if self._paused or self.at_end(now):
            return None
        position, n = self.position(now), self._n_frames
        if self.loop and n is not None:
            position %= n
        return position / self.fps

    def frame(self, now: float) -> int:
        """The frame to show at ``now``: wrapped when looping, held on the last one otherwise."""
        return self._wrap(self._floor(self.position(now)))

    def at_end(self, now: float) -> bool:
        """Without looping: playback has reached the last frame and stays there."""
        n = self._n_frames
        return not self.loop and n is not None and self._floor(self.position(now)) >= n - 1

    def pause(self, now: float) -> None:
        if not self._paused:
            self._set(now, self._normalised(self.position(now)))
            self._paused = True

    def resume(self, now: float) -> None:
        """Play from where it stands (from frame 0 when stopped at the end without looping)."""
        if self.at_end(now):
            self._set(now, 0.0)
        elif self._paused:
            self._set(now, self._origin)
        self._paused = False

    def toggle(self, now: float) -> None:
        """Space: pause if playing, play if paused."""
        if self._paused or self.at_end(now):
            self.resume(now)
        else:
            self.pause(now)

    def step(self, now: float, delta: int = 1) -> int:
        """Pause, and move ``delta`` frames from the frame shown; return the new frame.

        Past either end it wraps when looping and the length is known, else it stops there.
        """
        target = self.frame(now) + delta
        n = self._n_frames
        if n is None:
            target = max(target, 0)
        elif self.loop:
            target %= n
        else:
            target = min(max(target, 0), n - 1)
        self._paused = True
        self._set(now, float(target))
        return target

    def seek(self, now: float, frame: int) -> None:
        """Show ``frame`` now, keeping play or pause."""
        self._set(now, float(self._wrap(max(int(frame), 0))))

    def home(self, now: float) -> None:
        """Home: back to frame 0, keeping play or pause."""
        self.seek(now, 0)

    def next_change(self, now: float) -> float | None:
        """When the shown frame next changes (None while paused or stopped at the end)."""
        if self._paused or self.at_end(now):
            return None
        following = self._floor(self.position(now)) + 1
        return self._anchor + (following - self._origin) / self.fps

    def _set(self, now: float, position: float) -> None:
        self._anchor, self._origin = now, position

    def _normalised(self, position: float) -> float:
        """The same frame (and phase within it), wrapped into [0, n) when looping."""
        n = self._n_frames
        if n is None:
            return max(position, 0.0)
        if self.loop:
            return position % n
        return min(position, n - 1.0)

    def _wrap(self, frame: int) -> int:
        n = self._n_frames
        if n is None:
            return max(frame, 0)
        if self.loop:
            return frame % n
        return min(max(frame, 0), n - 1)

    @staticmethod
    def _floor(position: float) -> int:
        # A hair of tolerance, so that a position computed to land on a frame boundary (as
        # next_change's time does) is on the new frame rather than 1e-16 short of it.
        return math.floor(position + 1e-9)


# -- random access to the frames of a take --------------------------------------------------


class HeldTable:
    """The held FAP state of every frame of a take, read lazily, for deforming any frame.

    Row *k* is the state a player holds at frame *k* (FAP 1 / 2 expanded), as 68 low-level FAP
    values limited to what the face can follow (``FapEngine.limit``) in float32 (272 bytes a frame), kept in fixed-size chunks. The file is read forward
    only as far as asked (``ensure``, ``read_ahead``); ``pose(k)`` deforms frame *k* as
    ``FapPlayback`` does on its way through (up to the float32 rounding of the FAP values).
    """

    CHUNK = 4096

    def __init__(self, path: str | os.PathLike, runtime: Runtime,
                 declared_frames: int | None = None) -> None:
        self.path = Path(path)
        self.runtime = runtime
        self.declared_frames = declared_frames
        self._chunks: list[np.ndarray] = []
        self._count = 0
        self._reader: FapReader | None = iter_fap(self.path)
        self._held = held_low_level(self._reader)

    @property
    def count(self) -> int:
        """Frames read so far."""
        return self._count

    @property
    def complete(self) -> bool:
        """The whole file has been read: ``count`` is the take's length."""
        return self._reader is None

    @property
    def total(self) -> int | None:
        """The take's length if known, else the header's declared count (None without one)."""
        return self._count if self.complete else self.declared_frames

    @property
    def nbytes(self) -> int:
        return sum(chunk.nbytes for chunk in self._chunks)

    def ensure(self, n: int) -> bool:
        """Read until at least ``n`` frames are known or the file ends; True if there are."""
        while self._count < n and self._read_one():
            pass
        return self._count >= n

    def read_ahead(self, deadline: float) -> None:
        """Read further frames until ``time.perf_counter()`` passes ``deadline`` or the end."""
        while not self.complete and time.perf_counter() < deadline:
            for _ in range(16):
                if not self._read_one():
                    return

    def low_level(self, k: int) -> np.ndarray:
        """The 68 held low-level FAP values of frame ``k`` (reading the file that far)."""
        if k < 0 or not self.ensure(k + 1):
            raise IndexError(f"frame {k}: the take has {self._count} frames")
        return self._chunks[k // self.CHUNK][k % self.CHUNK]

    def mesh(self, k: int, normals: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Vertices and normals of frame ``k``; with ``normals`` off, (vertices, None): for a
        renderer whose draw sums them (``gpu_normals``)."""
        return self.runtime.deform_pose(Pose(self.low_level(k).astype(np.float64)), normals=normals)

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def _read_one(self) -> bool:
        """Read one frame into the table; False (and close the file) at its end."""
        if self._reader is None:
            return False
        try:
            values = next(self._held, None)
        except FapError as error:
            warnings.warn(f"{error}; playing the {self._count} frames before it", FapWarning,
                          stacklevel=2)
            values = None
        if values is None:
            self.close()
            return False
        row, column = divmod(self._count, self.CHUNK)
        if row == len(self._chunks):
            self._chunks.append(np.empty((self.CHUNK, N_FAPS), dtype=np.float32))
        self._chunks[row][column] = self.runtime.faps.shown(values)  # float32 holds what a face shows
        self._count += 1
        return True


# -- the window ------------------------------------------------------------------------------


def check_display(environ: Mapping[str, str] | None = None, platform: str | None = None) -> None:
    """Raise ``NoDisplayError`` where a window plainly cannot open (X11/Wayland without either)."""
    environ = os.environ if environ is None else environ
    platform = sys.platform if platform is None else platform
    if not platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return
    if not environ.get("DISPLAY") and not environ.get("WAYLAND_DISPLAY"):
        raise NoDisplayError("no display to open a window on (DISPLAY is not set)")


def open_window(title: str, size: tuple[int, int], backends: tuple[str, ...] = BACKENDS) -> Any:
    """A moderngl-window window with a GL 3.3 context, or ``WindowError`` saying why not.

    Each backend in turn, with a 4x multisampled framebuffer and then a plain one. Software GL
    (Mesa's llvmpipe, e.g. under Xvfb or in a VM) gets the plain one: there multisampling
    triples the cost of a frame.
    """
    check_display()
    with warnings.catch_warnings():  # moderngl-window 3.1 imports PyGLM the way it deprecates
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        import moderngl_window

    failures: list[tuple[str, BaseException]] = []
    for backend in backends:
        try:
            window_cls = moderngl_window.get_local_window_cls(backend)
        except ModuleNotFoundError as error:
            if backend != backends[0] and error.name == backend:
                continue  # an optional fallback that is not installed
            failures.append((backend, error))
            continue
        except Exception as error:  # pyglet connects to the display on import
            failures.append((backend, error))
            continue
        for samples in (4, 0):
            try:
                window = window_cls(title=title, size=size, resizable=True, vsync=True,
                                    samples=samples, gl_version=(3, 3), cursor=True)
            except Exception as error:
                failures.append((backend, error))
                continue
            if samples and software_rasteriser(window.ctx):
                window.close()
                window.destroy()
                continue
            moderngl_window.activate_context(window=window)
            return window
    backend, error = failures[0] if failures else (backends[0], RuntimeError("no backend"))
    display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    reason = f"{type(error).__name__}: {error}".rstrip(": ")
    if "display" in type(error).__name__.lower():
        raise NoDisplayError(f"cannot connect to the display {display!r}") from error
    raise WindowError(f"cannot open an OpenGL 3.3 window with {backend} ({reason})") from error


class Player:
    """A take in a window: the loop, the keys and the title. ``run()`` returns when closed.

    The loop draws only when the frame or the window's size changed (and at least every
    ``REFRESH`` seconds, for a window uncovered); in between it only handles events, where the
    backend allows that without a buffer swap (pyglet), so a paused player is nearly idle. A
    resized window gets a renderer of its new size, the camera re-aimed for its aspect.
    """

    REFRESH = 0.25

    def __init__(self, playback: FapPlayback, window: Any, view: str = "front",
                 table: HeldTable | None = None, loop: bool = True, outputs: Sequence[LiveOutput] = ()) -> None:
        self.playback = playback
        self.outputs = list(outputs)  # what else each frame goes to (the show server), even minimised
        self._published: int | None = None
        self.face = playback.face
        self.window = window
        self.view = view
        if table is None:
            table = HeldTable(playback.path, playback.runtime, playback.header.declared_frames)
        self.table = table
        self.clock = PlayClock(playback.fps, self._known_length(), loop=loop,
                               now=time.perf_counter())
        self.renderer: Renderer | None = None
        self._quit = False
        self._shown: int | None = None
        self._pose: tuple[np.ndarray, np.ndarray] | None = None
        self._drawn_at = -math.inf
        self._title = ""
        self.bar = PlayBar(window)
        self._bar_shown: tuple[str, bool] | None = None
        # moderngl-window's pyglet window keeps the pyglet one as ``_window``: its events can be
        # handled without drawing. Other backends handle them in swap_buffers only.
        native = getattr(window, "_window", None) if window.name == "pyglet" else None
        self._dispatch_events = getattr(native, "dispatch_events", None)
        window.exit_key = None  # Escape is ours, so that GL objects go before the context
        window.key_event_func = self._on_key

    def run(self) -> None:
        window = self.window
        sound = self._sound()
        try:
            if min(window.buffer_size) > 0:
                self._make_renderer(tuple(window.buffer_size))
            self.clock.seek(time.perf_counter(), 0)
            if sound is not None and not sound.start(lambda line: print(f"puppet play: {line}", file=sys.stderr)):
                sound = None
            while not (self._quit or window.is_closing):
                self._update()
                self._idle()
        finally:
            if sound is not None:
                sound.close()
            if self.renderer is not None:
                self.renderer.release()
                self.renderer = None
            self.bar.release()
            self.table.close()
            close_outputs(self.outputs)
            window.close()
            window.destroy()

    def _sound(self) -> ClockedSound | None:
        """The take's sound, following this player's clock (None for a take without sound)."""
        track = soundtrack(self.playback.path)
        return None if track is None else ClockedSound(track, self.clock.seconds)

    def _update(self) -> None:
        """Draw the frame due now if anything changed; handle the window's events."""
        now = time.perf_counter()
        size = tuple(self.window.buffer_size)
        k = self._frame_now(now)
        self._set_title(k)
        for output in self.outputs:
            output.service()
        if min(size) < 1:  # minimised
            self._publish(k, None)
            return self._events()
        bar = (play_status(k, self.table.total, self.clock.fps, self.clock.paused), self.bar.visible)
        stale = (self.renderer is None or self.renderer.size != size or k != self._shown
                 or bar != self._bar_shown or now - self._drawn_at > self.REFRESH)
        if not stale and self._dispatch_events is not None:
            return self._events()
        if self.renderer is None or self.renderer.size != size:
            self._make_renderer(size)
        if k != self._shown:
            self._pose, self._shown = self.table.mesh(k, normals=not self.renderer.gpu_normals), k
        self._publish(k, self._pose[0])
        self.renderer.draw(*self._pose, framebuffer=self.window.fbo)
        self.bar.draw(bar[0])
        self._drawn_at, self._bar_shown = now, bar
        self.window.swap_buffers()  # also handles the window's events

    def _publish(self, k: int, vertices: np.ndarray | None) -> None:
        """Frame ``k`` to the outputs, once (its vertices made here when the window drew none)."""
        if not self.outputs or k == self._published:
            return
        if vertices is None:
            vertices = self.table.mesh(k, normals=False)[0]
        status = {"take": self.playback.path.name, "frame": k, "frames": self.table.total,
                  "paused": self.clock.paused}
        for output in self.outputs:
            output.publish(vertices, status)
        self._published = k

    def _events(self) -> None:
        if self._dispatch_events is not None:
            self._dispatch_events()
        else:
            self.window.swap_buffers()

    def _frame_now(self, now: float) -> int:
        if not self.table.complete:
            # Read up to the frame due (and one past it, to find an end that falls there).
            self.table.ensure(math.floor(self.clock.position(now)) + 2)
            self.clock.n_frames = self._known_length()
        return self.clock.frame(now)

    def _known_length(self) -> int | None:
        return self.table.count if self.table.complete and self.table.count else None

    def _idle(self) -> None:
        """Read ahead in the file, then sleep until the next frame is due (or keys are)."""
        now = time.perf_counter()
        wake = now + (IDLE_WAKE if self._dispatch_events is not None else 2 * IDLE_WAKE)
        due = self.clock.next_change(now)
        if due is not None:
            wake = min(wake, due)
        self.table.read_ahead(wake - 0.002)
        if self.table.complete and self.clock.n_frames is None:
            self.clock.n_frames = self._known_length()
        delay = wake - time.perf_counter()
        if delay > 0:
            time.sleep(delay)

    def _make_renderer(self, size: tuple[int, int]) -> None:
        if self.renderer is not None:
            self.renderer.release()
        face = self.face
        self.renderer = Renderer.for_face(face, width=size[0], height=size[1], ctx=self.window.ctx)
        aim_at_head(self.renderer, face, self.view)
        self.window.fbo.viewport = (0, 0, *size)

    def _on_key(self, key: Any, action: Any, modifiers: Any) -> None:
        keys = self.window.keys
        if action != keys.ACTION_PRESS:
            return
        now = time.perf_counter()
        if key in (keys.Q, keys.ESCAPE):
            self._quit = True
        elif key == keys.SPACE:
            self.clock.toggle(now)
        elif key == keys.RIGHT:
            self._step(now, 1)
        elif key == keys.LEFT:
            self._step(now, -1)
        elif key == keys.HOME:
            self.clock.home(now)
        elif key == keys.H:
            self.bar.toggle()

    def _step(self, now: float, delta: int) -> None:
        if delta > 0 and not self.table.complete:
            self.table.ensure(self.clock.frame(now) + delta + 2)
            self.clock.n_frames = self._known_length()
        self.clock.step(now, delta)

    def _set_title(self, k: int) -> None:
        title = window_title(self.playback.path.name, k, self.table.total, self.clock.fps,
                             self.clock.paused)
        if title != self._title:
            self.window.title = self._title = title


def window_title(name: str, frame: int, total: int | None, fps: float, paused: bool) -> str:
    """``demo.fap | frame 12/98 | 25 fps | paused``; frames counted from 1, "?" for no total."""
    parts = [name, f"frame {frame + 1}/{'?' if total is None else total}", f"{fps:g} fps"]
    if paused:
        parts.append("paused")
    return " | ".join(parts)


def play_take(path: str | os.PathLike, *, size: tuple[int, int] = (960, 720),
              view: str = "front", face: Face | None = None,
              outputs: Callable[[Face], Sequence[LiveOutput]] | None = None) -> None:
    """Play a .fap take in a window in real time, looping, until Q / Escape or closing it.

    ``outputs`` makes, from the face played, what else each frame goes to (the show server).

    Everything is checked before the window opens (the take, its first frame, the display).
    Without a usable display this prints ``puppet play: <why>; use 'puppet render ...'`` on
    stderr and raises ``SystemExit(2)``.
    """
    if view not in VIEWS:
        raise ValueError(f"view {view!r}: expected one of {VIEWS}")
    playback = FapPlayback(path, face)
    table = HeldTable(playback.path, playback.runtime, playback.header.declared_frames)
    try:
        if not table.ensure(1):
            _exit(f"{playback.path}: the take holds no frames")
        try:
            check_display()
        except NoDisplayError as error:
            _exit(f"{error}; {RENDER_HINT}")
        title = window_title(playback.path.name, 0, table.total, playback.fps, False)
        try:
            window = open_window(title, size)
        except WindowError as error:
            _exit(f"{error}; {RENDER_HINT}")
    except BaseException:
        table.close()
        raise
    try:
        made = list(outputs(playback.face)) if outputs is not None else []
    except BaseException:
        table.close()
        window.close()
        window.destroy()
        raise
    print("keys: space pause/play, right/left step a frame, Home first frame, H hide the status line, Q/Esc quit",
          file=sys.stderr)
    try:
        Player(playback, window, view, table, outputs=made).run()
    except KeyboardInterrupt:  # Ctrl+C in the terminal closes the window like Q
        pass


def _exit(message: str) -> None:
    print(f"puppet play: {message}", file=sys.stderr)
    raise SystemExit(2)
