"""The live rig in a window: ``puppet live --mapping M.yaml``.

``run_live`` opens a window (``window.open_window``, with ``window.check_display`` first, as
``puppet play`` does) and a ``LiveSession`` for the mapping, and draws ``session.frame()`` every
display frame (paced by the window's vsync).

The window is the cockpit (``puppet.view.overlay``, drawn over the face with Dear ImGui): fps and
input-to-photon latency with rolling graphs, each device's state and why it is LOST, REC with the
take's name and time, the channel monitor (M) and the keys; H hides it. The title says the same in
short for window managers' task bars: ``<mapping> | 60 fps | 12.3 ms | box: open | REC take_001``
-- the measured frame rate, the latency from the newest Sample to the frame drawn (median over the
last second; "-- ms" until samples arrive), each device's state, and the take while recording.

Keys: R starts a take (named ``--record NAME``, default "take": folders ``NAME_001``...) and
stops it; N neutral pose (``session.neutral()``: every channel back to rest, in the take too); K
calibrates in the window (``calibrate.GuidedCalibration``: rest, then sweep, guided in the cockpit,
written into the mapping and used from the next frame); M toggles the channel monitor (raw and shaped bars per channel, and their targets); H the whole
overlay; Q or Escape quits, finishing any take first so it is complete.

C re-centres the bipolar channels (sticks) where they rest now, undoing drift
(``session.recentre()``, logged in the take); a full calibration of a channel's range is K, or
``puppet calibrate --mapping M.yaml``.

Every other key -- the digits, the other letters, F1-F12 but F11 (full screen) -- is pressed and
released on the session's ``keys://`` devices (``devices.keys_device``), so a mapping can hold,
toggle or play a pose on it (its ``triggers``); the cockpit shows each trigger's level.

No display: a one-line message on stderr and ``SystemExit(2)``, as ``puppet play``.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from devices.keys_device import KeysDevice, key_channels
from puppet.io.shipped import mappings_folder
from puppet.io.takes import TakeError, check_take_name
from puppet.live.calibrate import CalibrationError, GuidedCalibration, calibration_channels, device_overrides
from puppet.live.mappingfile import load_mapping
from puppet.view.liveoutput import HeadlessLive, LiveOutput, close_outputs, live_status, publish, saved_line
from puppet.view.overlay import Cockpit, device_lines
from puppet.view.renderer import Renderer
from puppet.view.rendertake import VIEWS, aim_at_head
from puppet.view.window import NoDisplayError, WindowError, check_display, open_window

WINDOW_S = 1.0
"""The span, in seconds, of the measured fps and the latency median."""

FAILURE_S = 20.0
"""How long the cockpit shows a failure (a calibration not written, or channels left as they were)."""


class LiveStats:
    """Frames drawn and sample->drawn latencies over the last ``WINDOW_S`` (times in ns)."""

    def __init__(self, span_ns: int = int(WINDOW_S * 1e9)) -> None:
        self.span_ns = span_ns
        self._frames: deque[int] = deque()
        self._latency: deque[tuple[int, int]] = deque()

    def drawn(self, now_ns: int, newest_sample_ns: int | None, new_samples: bool) -> None:
        self._frames.append(now_ns)
        if new_samples and newest_sample_ns is not None:
            self._latency.append((now_ns, now_ns - newest_sample_ns))
        cut = now_ns - self.span_ns
        while self._frames and self._frames[0] <= cut:
            self._frames.popleft()
        while self._latency and self._latency[0][0] <= cut:
            self._latency.popleft()

    @property
    def fps(self) -> float:
        return len(self._frames) * 1e9 / self.span_ns

    @property
    def latency_ms(self) -> float | None:
        if not self._latency:
            return None
        return statistics.median(v for _, v in self._latency) / 1e6


def live_title(name: str, fps: float, latency_ms: float | None, states: dict[str, Any],
               recording: str | None) -> str:
    """``arduino_sliders | 60 fps | 12.3 ms | box: open | REC take_001``."""
    parts = [name, f"{fps:.0f} fps", "-- ms" if latency_ms is None else f"{latency_ms:.1f} ms"]
    parts += [f"{dev}: {getattr(state, 'name', str(state)).lower()}" for dev, state in states.items()]
    if recording:
        parts.append(f"REC {recording}")
    return " | ".join(parts)


class LiveView:
    """A LiveSession in a window: the loop, keys and title. ``run()`` returns when closed.

    ``step()`` is one turn of the loop (tests call it directly on a headless window).
    """

    def __init__(self, session: Any, window: Any, view: str = "front", outputs: Sequence[LiveOutput] = ()) -> None:
        self.session = session
        self.outputs = list(outputs)
        self.window = window
        self.view = view
        self.name = Path(session.mapping_path).stem
        self.stats = LiveStats()
        self.renderer: Renderer | None = None
        self.cockpit = Cockpit(window)
        self.take: Path | None = None       # the folder being recorded
        self.takes: list[Path] = []         # finished takes
        self._quit = False
        self._take_started = 0.0
        self.calibration: GuidedCalibration | None = None
        self.notice, self._notice_until, self.notice_failed = "", 0.0, False
        self._title = ""
        window.exit_key = None  # Escape is ours: the take is finished before the window goes
        window.key_event_func = self._on_key
        self._key_names = key_channels(window.keys)  # key code -> keys:// channel

    def run(self) -> None:
        try:
            while not (self._quit or self.window.is_closing):
                self.step()
        finally:
            self.close()

    def step(self) -> None:
        window = self.window
        size = tuple(window.buffer_size)
        for output in self.outputs:
            output.service()
        frame = self.session.frame()
        if self.calibration is not None:
            self._calibrating()
        if min(size) > 0:
            if self.renderer is None or self.renderer.size != size:
                self._make_renderer(size)
            self.renderer.draw(frame.vertices, frame.normals, framebuffer=window.fbo)
            self._draw_cockpit(frame.states, frame.pose.t_ns)
        window.swap_buffers()  # handles the window's events too (keys)
        self._follow_take()
        self.stats.drawn(time.monotonic_ns(), frame.newest_sample_ns, frame.n_samples > 0)
        publish(self.outputs, frame, live_status(self.session, self.stats, frame))
        self._set_title(frame.states)

    def _follow_take(self) -> None:
        """A take started or stopped by other means than the R key (the control API), or one
        that stopped on its own (``record_error``): said on the terminal and in the cockpit."""
        session = self.session
        if self.take is None and session.recording:
            self.take, self._take_started = session.take_folder, time.monotonic()
            print(f"recording {self.take.resolve()}", file=sys.stderr)
        elif self.take is not None and not session.recording:
            if session.record_error:
                print(f"take not complete: {session.record_error}", file=sys.stderr)
            else:
                self.takes.append(self.take)
                print(f"take saved: {saved_line(self.take)}", file=sys.stderr)
            self.take = None

    def close(self) -> None:
        try:
            self._stop_recording()
        finally:
            close_outputs(self.outputs)
            if self.renderer is not None:
                self.renderer.release()
                self.renderer = None
            if self.cockpit is not None:
                self.cockpit.release()
                self.cockpit = None
            self.window.close()
            self.window.destroy()

    # -- keys --------------------------------------------------------------------------------

    def _on_key(self, key: Any, action: Any, modifiers: Any) -> None:
        keys = self.window.keys
        name = self._key_names.get(key)
        if name is not None and action in (keys.ACTION_PRESS, keys.ACTION_RELEASE):
            self._push_key(name, 1.0 if action == keys.ACTION_PRESS else 0.0)
        if action != keys.ACTION_PRESS:
            return
        if key in (keys.Q, keys.ESCAPE):
            self._stop_recording()
            self._quit = True
        elif key == keys.R:
            if self.session.recording:
                self._stop_recording()
            else:
                try:
                    self.session.start_recording()
                except TakeError as error:  # an unwritable folder: say so, keep performing
                    print(f"not recording: {error}", file=sys.stderr)
                else:
                    self._follow_take()
        elif key == keys.N:
            self.session.neutral()
        elif key == keys.C:
            self.session.recentre()
            print("sticks re-centred where they rest", file=sys.stderr)
        elif key == keys.M:
            self.cockpit.monitor = not self.cockpit.monitor
        elif key == keys.H:
            self.cockpit.toggle()
        elif key == keys.K and self.calibration is None:
            self._start_calibration()

    def _push_key(self, name: str, value: float) -> None:
        """A key pressed (1) or released (0) on every ``keys://`` device of the session."""
        for device in self.session.devices.values():
            if isinstance(device, KeysDevice):
                device.push({name: value})

    def _stop_recording(self) -> None:
        if self.session.recording:
            folder = self.session.stop_recording()
            self.takes.append(Path(folder))
            print(f"take saved: {saved_line(folder)}", file=sys.stderr)
        self.take = None

    # -- calibration from the window ------------------------------------------------------------

    def _start_calibration(self) -> None:
        """K: ``puppet calibrate``'s rest-then-sweep, guided in the cockpit, written into the
        mapping when it ends (not while recording; a shipped mapping is copied first)."""
        path = Path(self.session.mapping_path)
        if self.session.recording:
            self._say("calibrate: stop recording first (R)")
        elif path.resolve().parent == mappings_folder().resolve():
            self._say(f"calibrate: {path.stem} is a shipped mapping; calibrate a copy "
                      f"(puppet mappings --copy {path.stem})")
        else:
            self.calibration = GuidedCalibration(path, calibration_channels(self.session.mapping))
            for device in self.session.devices.values():  # a simulated hand (sim://...&motion=calibrate)
                restart = getattr(device, "restart_motion", None)  # follows the steps, as a performer does
                if restart is not None:
                    restart()

    def _calibrating(self) -> None:
        calibration = self.calibration
        calibration.feed(self.session.mapping.channels())
        if calibration.phase()[0] != "done":
            self.notice, self.notice_failed = calibration.instruction(), False
            self._notice_until = time.monotonic() + 0.5
            return
        self.calibration = None
        try:
            result, warnings = calibration.finish()
        except (CalibrationError, OSError) as error:
            self._say(f"calibration not written: {error}", FAILURE_S, failed=True)
            return
        self.session.mapping = load_mapping(calibration.path)  # the new ranges from the next frame on
        for line in warnings:
            print(f"calibrate: {line}", file=sys.stderr)
        first = f": {warnings[0]}" + (" ..." if len(warnings) > 1 else "") if warnings else ""
        self._say(f"calibrated {len(result) - len(warnings)} of {len(result)} channels into "
                  f"{calibration.path.name} ({len(warnings)} left as they were{first})",
                  FAILURE_S if warnings else 6.0, failed=bool(warnings))

    def _say(self, text: str, seconds: float = 6.0, failed: bool = False) -> None:
        """A notice in the cockpit for ``seconds`` (and on the terminal); ``failed`` draws it as a
        failure (red), so a calibration that left channels as they were is not missed."""
        self.notice, self._notice_until, self.notice_failed = text, time.monotonic() + seconds, failed
        print(text, file=sys.stderr)

    # -- drawing -----------------------------------------------------------------------------

    def _make_renderer(self, size: tuple[int, int]) -> None:
        if self.renderer is not None:
            self.renderer.release()
        face = self.session.runtime.face
        self.renderer = Renderer.for_face(face, width=size[0], height=size[1], ctx=self.window.ctx)
        aim_at_head(self.renderer, face, self.view)
        self.session.normals = not self.renderer.gpu_normals
        self.window.fbo.viewport = (0, 0, *size)

    def _draw_cockpit(self, states: dict[str, Any], pose_ns: int | None = None) -> None:
        self.cockpit.tick(self.stats.fps, self.stats.latency_ms)
        if not self.cockpit.visible:  # hidden: nothing gathered, nothing drawn
            return
        recording = None
        if self.take is not None and self.session.recording:
            recording = (self.take.name, time.monotonic() - self._take_started)
        channels = self.session.mapping.channels() if self.cockpit.monitor else ()
        notice = self.notice if time.monotonic() < self._notice_until else ""
        self.cockpit.draw(self.stats.fps, self.stats.latency_ms, device_lines(states, self.session.devices),
                          recording, channels, notice, layer=self.session.layer_status(), failed=self.notice_failed,
                          triggers=self.session.mapping.trigger_states(pose_ns))

    def _set_title(self, states: dict[str, Any]) -> None:
        recording = self.take.name if self.take is not None and self.session.recording else None
        title = live_title(self.name, self.stats.fps, self.stats.latency_ms, states, recording)
        if title != self._title:
            self.window.title = self._title = title


def trigger_keys(session: Any) -> str:
    """The triggers on the session's ``keys://`` devices, as the terminal says them: ``1 joy, 7 pout``."""
    keyed = []
    for name, spec in session.mapping.triggers.specs.items():
        device, _, key = (spec.source or "").partition(".")
        if isinstance(session.devices.get(device), KeysDevice):
            keyed.append(f"{key} {name}")
    return ", ".join(keyed)


def open_session(mapping_path: str | os.PathLike, *, record: str | None = None, fps: int = 30,
                 devices: dict[str, str] | None = None, record_root: str | os.PathLike | None = None,
                 face: Any = None, layer_over: str | os.PathLike | None = None, arm: list[str] = ()):
    """A LiveSession; ``devices`` replaces mapping devices by name with other URLs."""
    from devices import open_device
    from puppet.live.session import LiveSession

    opened = {}
    try:
        for name, url in (devices or {}).items():
            opened[name] = open_device(url, name)
        return LiveSession(mapping_path, face=face, devices=opened, record_root=record_root,
                           take_name=record or "take", fps=fps, layer_over=layer_over, arm=arm)
    except BaseException:
        for device in opened.values():
            device.close()
        raise


def run_live(mapping_path: str | os.PathLike, *, record: str | None = None, fps: int = 30,
             size: tuple[int, int] = (960, 720), view: str = "front",
             devices: dict[str, str] | None = None,
             record_root: str | os.PathLike | None = None, face: Any = None,
             layer_over: str | os.PathLike | None = None, arm: list[str] = (),
             outputs: Callable[[Any], Sequence[LiveOutput]] | None = None, window: bool = True) -> None:
    """Run the mapping's devices onto the face in a window until Q / Escape or closing it.

    ``devices`` overrides device URLs by name (e.g. ``{"box": "sim://joystick?..."}``); takes go
    under ``record_root`` (default ``takes/``); ``face`` is the face to perform (default the
    embedded one; ``load_face`` of a face folder or mesh); ``layer_over`` and ``arm`` record layered passes
    over an earlier take (``puppet.live.takeclock.Layer``). ``outputs`` makes, from the open
    session, what else each frame goes to (``LiveOutput``s: the show server); ``window`` False
    runs the loop for them alone, with no window, until Ctrl+C (``HeadlessLive``). The mapping is
    checked first, then the display, then the session opens (devices, face, base take), and only then the window: a bad
    input is one error, never a window that closes again. Without a usable display this prints
    ``puppet live: <why>`` on stderr and raises ``SystemExit(2)``.
    """
    if view not in VIEWS:
        raise ValueError(f"view {view!r}: expected one of {VIEWS}")
    device_overrides(mapping_path, load_mapping(mapping_path).devices, devices or {})
    check_take_name(record or "take")
    if window:
        try:
            check_display()
        except NoDisplayError as error:
            _exit(str(error))
    session = open_session(mapping_path, record=record, fps=fps, devices=devices,
                           record_root=record_root, face=face, layer_over=layer_over, arm=arm)
    made: list[LiveOutput] = []
    try:
        made = list(outputs(session)) if outputs is not None else []
        shown = open_window(Path(mapping_path).stem, size) if window else None
    except BaseException as error:
        close_outputs(made)
        session.close()
        if isinstance(error, WindowError):
            _exit(str(error))
        raise
    print(f"takes go to {session.record_root.resolve()}", file=sys.stderr)
    print(session.mapping.idle.describe() if session.mapping.idle is not None else "idle life: off",
          file=sys.stderr)
    if shown is None:
        print("no window: Ctrl+C ends (a take being recorded is finished first)", file=sys.stderr)
        live = HeadlessLive(session, made, LiveStats())
    else:
        print("keys: R record/stop, N neutral, C re-centre sticks, K calibrate, M channel monitor, "
              "H hide the overlay, Q/Esc quit", file=sys.stderr)
        keyed = trigger_keys(session)
        if keyed:
            print(f"the mapping's keys: {keyed}", file=sys.stderr)
        live = LiveView(session, shown, view, made)
    try:
        live.run()
    except KeyboardInterrupt:  # Ctrl+C closes like Q (run's finally finishes the take)
        pass
    finally:
        session.close()


def _exit(message: str) -> None:
    print(f"puppet live: {message}", file=sys.stderr)
    raise SystemExit(2)
