"""The live session: devices in, a deformed face out, once per frame, with an optional take.

``LiveSession(mapping_path)`` loads the mapping, opens every device it names (``open_device``;
``devices=`` replaces some or all of them by name, for tests) and starts their reader threads.
``session.frame()`` is one turn of the live loop:

1. drain every device (``Device.drain`` never blocks and empties the queue, so nothing queued
   grows however slowly the loop runs), merging the devices' Samples in timestamp order;
2. feed each Sample to the mapping (and, while recording, to the take's raw log; frame ticks
   that fall before a Sample are written first, see *Recording*);
3. take the mapping's Pose at ``now`` and deform the face into buffers allocated once
   (``LiveFrame.vertices`` / ``LiveFrame.normals`` *are* those buffers: copy them to keep a frame).

Holding the pose
    While every device is OPEN the Pose is taken at ``now``, so smoothing settles between
    samples. While any device is not OPEN (LOST, or OPENING between reconnection attempts) the
    pose time is frozen at the last frame taken with every device open: the lost device's
    channels (no new samples) give exactly the values of that frame, so the face holds still
    instead of drifting on filter previews; other devices' new samples still come through at
    their filtered values, and the triggers play on at ``now`` (a key pressed while the slider
    box is away still smiles), and so does idle life (blinks, eyes, breath:
    ``puppet.live.idlelife``): the performed channels hold, the face does not freeze mid-blink.
    When the device is back (OPEN) the clock runs again.

Recording
    ``start_recording()`` opens a ``TakeRecorder`` and a ``TakeClock`` (``puppet.live.takeclock``):
    tick k of the take is at ``t0 + k / fps`` (t0: the clock when recording started), written
    *between* the Samples, so the .fap has exactly ``fps`` frames per second of take time
    whatever the loop rate, and a slow loop still writes the poses the performer made. Every
    Sample goes to the take's raw log, and so does every other thing that decides a frame --
    a device lost (``hold``: the gap in the take) or back (``resume``), the neutral key
    (``reset``), a trigger fired by name (``trigger``, see ``LiveSession.trigger``), a loop frame
    that wrote ticks (``frame``) -- together with the mapping's state
    at t0 in the take's metadata, so that ``puppet.live.retake`` rebuilds the .fap exactly.
    ``layer=`` (a ``takeclock.Layer``) records a pass over an earlier take: the face shows and
    the take gets the base take's frames with the armed FAPs replaced by the live pose.
Floods
    Mapping a Sample costs the loop about 10 µs, so a device sending thousands a second would
    starve the face. A frame that drains more than ``FLOOD`` Samples takes each channel's newest
    reading instead (``Mapping.feed_newest``: the filters step once per frame of the take, or
    of the loop when not recording; buttons and trigger sources still see every reading), and
    keeps drawing. Nothing is lost: every Sample still goes to the take's raw log, marked as a
    run (``newest``) so a replay takes it the same way, and the log is written by a thread of
    its own (``SampleLogWriter``), so the loop only queues each line. At calm rates every
    reading is mapped, as before.
Faults
    A write to the take that fails in any way ends the take, marked incomplete with the error
    (``record_error``), and the live face goes on; a frame that fails while recording ends the
    take the same way before the error goes on up, so a take is only ever marked complete when
    it was stopped normally. A mapping value that comes out NaN (``Mapping.held_values``) holds
    its last good value, in the face and the take, and is reported once (``pose_error`` and a
    warning), not per frame.
Muscles
    ``Pose.muscles`` is drawn with the FAPs in one frame (the runtime's control-point mode,
    ``Runtime.deform(..., muscles=)``), and a take writes it as the FAPs the muscles' motion
    measures (``Runtime.muscle_faps``, see ``puppet.live.takeclock``). A mapping naming a muscle this
    face lacks is refused before any device opens.

``measure_latency(session, renderer, seconds)`` times input-to-frame latency: from the newest
Sample's timestamp (``time.monotonic_ns()`` right after the device's read returned) to the mesh
being ready, and to the frame drawn and read back (``renderer.render``).
"""

from __future__ import annotations

import collections
import heapq
import os
import statistics
import threading
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from devices import Device, State, open_device
from devices.base import Sample
from puppet.fap.pose import Pose
from puppet.io.samplelog import LogEvent
from puppet.io.takes import TakeError, TakeRecorder, take_fap
from puppet.live.mappingfile import load_mapping
from puppet.live.takeclock import Layer, TakeClock
from puppet.runtime.runtime import Runtime


@dataclass
class LiveFrame:
    """One frame of the live loop. ``vertices`` and ``normals`` are the session's buffers,
    overwritten by the next frame (``normals`` None where the session computes none:
    ``LiveSession.normals``); ``newest_sample_ns`` is the newest Sample ever fed (None before
    any); ``n_samples`` how many Samples this frame fed, ``sample_ns`` their timestamps."""

    vertices: np.ndarray
    normals: np.ndarray | None
    pose: Pose
    t_ns: int
    newest_sample_ns: int | None
    states: dict[str, State] = field(default_factory=dict)
    n_samples: int = 0
    sample_ns: tuple[int, ...] = ()


class LiveSession:
    """Devices -> mapping -> face runtime, one ``frame()`` at a time; optionally recording a take."""

    FLOOD = 100
    """More Samples than this in one frame is a flood: each channel takes its newest reading
    (per frame, the filters stepped once) instead of every reading (see *Floods*)."""

    def __init__(self, mapping_path: str | os.PathLike, *, face=None,
                 devices: dict[str, Device] | None = None, record_root: str | os.PathLike | None = None,
                 take_name: str = "take", fps: int = 30, layer_over: str | os.PathLike | None = None,
                 arm: list[str] | tuple[str, ...] = ()) -> None:
        self.mapping_path = Path(mapping_path)
        self.mapping = load_mapping(mapping_path)  # checked before anything opens
        self.layer = None if layer_over is None else Layer.armed(take_fap(layer_over), self.mapping, arm)
        if isinstance(face, Runtime):
            self.runtime = face
        else:
            if face is None:
                from puppet.face.load import load_face

                face = load_face()
            self.runtime = Runtime(face)
        missing = [m for m in self.mapping.muscle_names if m not in self.runtime.muscle_names]
        if missing:
            raise ValueError(f"{self.mapping_path}: this face has no muscle {missing[0]!r} "
                             f"(it has {', '.join(self.runtime.muscle_names) or 'none'})")
        self.record_root = Path(record_root) if record_root is not None else Path("takes")
        self.take_name, self.fps = take_name, fps

        overrides = dict(devices or {})
        for name, device in overrides.items():
            if device.name != name:
                raise ValueError(f"device override {name!r}: the device is named {device.name!r}, so its "
                                 f"Samples would not reach the mapping's {name!r} channels")
        self.devices: dict[str, Device] = {}
        self.urls: dict[str, str] = {}
        self._wake = threading.Event()  # set by every device when it queues a Sample
        try:
            for name, url in self.mapping.devices.items():
                self.devices[name] = overrides.pop(name) if name in overrides else open_device(url, name)
            for name, device in overrides.items():  # extra devices: read (and logged), not mapped
                self.devices[name] = device
            for name, device in self.devices.items():
                self.urls[name] = device.url or f"override:{type(device).__name__}"
            for device in self.devices.values():
                device.wake = self._wake
                device.start()
        except BaseException:
            self._close_devices()
            raise

        self._vertices = np.empty_like(self.runtime.rest)
        self._normals = np.empty_like(self.runtime.rest)
        self._with_normals = True
        self._hold_ns: int | None = None    # pose time of the last frame with every device open
        self._held = False                  # whether the pose is held (a device away)
        self._last_pose_ns: int | None = None
        self._have_mesh = False
        self._reset_at: int | None = None   # the neutral key, applied at the next frame
        self._recentre_at: int | None = None  # the recalibrate key, likewise
        self._triggered: collections.deque[LogEvent] = collections.deque()  # by name (``trigger``), for the next frame
        self.newest_sample_ns: int | None = None
        self.samples_fed = 0
        self.frames = 0
        self._recorder = None
        self._clock: TakeClock | None = None
        self.record_error: str | None = None  # why the last take stopped on its own
        self.pose_error: str | None = None    # the first mapping value held because it was NaN

    # -- the live loop ----------------------------------------------------------------------

    @property
    def normals(self) -> bool:
        """Whether frames carry vertex normals (the default); turned off for a renderer whose
        draw sums its own (``Renderer.gpu_normals``), which saves the frame their CPU time."""
        return self._with_normals

    @normals.setter
    def normals(self, on: bool) -> None:
        if bool(on) != self._with_normals:
            self._with_normals = bool(on)
            self._have_mesh = False  # a held pose's buffers lack (or need not) the normals

    def frame(self, now_ns: int | None = None) -> LiveFrame:
        """Drain, map, deform: one frame at ``now_ns`` (default: ``time.monotonic_ns()``)."""
        try:
            return self._frame(now_ns)
        except BaseException as exc:
            if self._recorder is not None:  # never leave a take that failed looking complete
                self._end_take(f"the live loop failed: {type(exc).__name__}: {exc}")
            raise

    def _frame(self, now_ns: int | None) -> LiveFrame:
        states = self.states
        batches = [d.drain() for d in self.devices.values()]
        now = time.monotonic_ns() if now_ns is None else int(now_ns)
        if all(s is State.OPEN for s in states.values()):
            pose_ns = now
            self._hold_ns = now
            if self._held:
                self._held = False
                self._apply(LogEvent(now, "resume"))
        else:
            pose_ns = now if self._hold_ns is None else min(now, self._hold_ns)
            if not self._held and self._hold_ns is not None:
                self._held = True
                away = {n: s.name.lower() for n, s in states.items() if s is not State.OPEN}
                self._apply(LogEvent(self._hold_ns, "hold", {"states": away}))
        if self._reset_at is not None:
            self._apply(LogEvent(self._reset_at, "reset"))
            self._reset_at = None
        if self._recentre_at is not None:
            self._apply(LogEvent(self._recentre_at, "recentre", {"centres": self.mapping.resting()}))
            self._recentre_at = None

        if len(batches) == 1:
            samples = batches[0]
        else:
            samples = list(heapq.merge(*batches, key=lambda s: s.t_ns))
        triggered = [self._triggered.popleft() for _ in range(len(self._triggered))]
        if len(samples) > self.FLOOD:
            self._apply_newest(samples)
            for event in triggered:
                self._apply(event)
        else:
            for entry in heapq.merge(samples, triggered, key=lambda e: e.t_ns) if triggered else samples:
                self._apply(entry)
        for sample in samples:
            if self.newest_sample_ns is None or sample.t_ns > self.newest_sample_ns:
                self.newest_sample_ns = sample.t_ns
        self.samples_fed += len(samples)
        if self._clock is not None and self._clock.due(now):
            self._apply(LogEvent(now, "frame"))

        pose = self.mapping.pose(pose_ns, now)
        if self.pose_error is None and self.mapping.held_values:
            self.pose_error = self.mapping.held_problem
            warnings.warn(self.pose_error, RuntimeWarning, stacklevel=2)
        # triggers and idle life play on while the pose is held
        playing = triggered or self.mapping.triggers or self.mapping.idle is not None
        if samples or playing or pose_ns != self._last_pose_ns or not self._have_mesh or self.layer is not None:
            shown = pose if self.layer is None else Pose(*self._layered(now, pose), pose.muscles)
            self.runtime.deform_pose(shown, out=self._vertices, normals_out=self._normals,
                                     normals=self._with_normals)
            self._have_mesh = True
        # else: nothing changed since the last frame (a held pose): the buffers already hold it
        self._last_pose_ns = pose_ns
        self.frames += 1
        normals = self._normals if self._with_normals else None
        return LiveFrame(self._vertices, normals, pose, now, self.newest_sample_ns, states, len(samples),
                         tuple(sample.t_ns for sample in samples))

    def wait_for_input(self, timeout: float) -> bool:
        """Wait until some device has a Sample queued (at most ``timeout`` seconds): a loop that
        starts its frame then, rather than on a clock of its own, shows a Sample as soon as it
        can. Returns whether one is there."""
        self._wake.clear()
        if any(device.backlog for device in self.devices.values()):
            return True
        return self._wake.wait(timeout)

    def neutral(self, now_ns: int | None = None) -> None:
        """Every channel back to rest (the neutral key), at the next frame (and so in the take)."""
        self._reset_at = time.monotonic_ns() if now_ns is None else int(now_ns)

    def recentre(self, now_ns: int | None = None) -> None:
        """Re-centre the bipolar channels where they are now (the recalibrate key: sticks let go
        of), at the next frame; the take logs the new centres."""
        self._recentre_at = time.monotonic_ns() if now_ns is None else int(now_ns)

    def trigger(self, name: str, action: str, now_ns: int | None = None) -> None:
        """Press, release or fire (a press and a release at once: a oneshot plays, a toggle
        flips) the mapping's trigger ``name`` at ``now_ns`` (default now), at the next frame, in
        time order with the Samples, and logged in the take so a replay does it too. Safe to
        call from another thread (the control API's). An unknown name or action is a
        ValueError naming the triggers there are (``mapping.trigger_names``)."""
        self.mapping.triggers.check(name, action)
        t = time.monotonic_ns() if now_ns is None else int(now_ns)
        self._triggered.append(LogEvent(t, "trigger", {"name": name, "action": action}))

    def _apply(self, entry: Sample | LogEvent) -> None:
        """One Sample or event: into the take (its log and its clock) while recording. A write
        that fails (disk full, the folder gone) ends the take, marked incomplete, and the live
        face goes on: ``record_error`` says what happened."""
        if self._into_take(lambda: self._take_entry(entry)):
            return
        if isinstance(entry, Sample):
            self.mapping.feed(entry)
        elif entry.kind == "reset":
            self.mapping.reset()
        elif entry.kind == "recentre":
            self.mapping.recentre(entry.data["centres"])
        elif entry.kind == "trigger" and entry.data["name"] in self.mapping.trigger_names:
            self.mapping.trigger(entry.data["name"], entry.data["action"], entry.t_ns)

    def _apply_newest(self, samples: list[Sample]) -> None:
        """A flood (more than ``FLOOD`` Samples in one frame): every Sample into the take's log
        (queued for its writer thread), marked as a run (``newest``), and the mapping takes
        each channel's newest reading per frame of the take (``TakeClock.apply_newest``), or
        per loop frame when not recording (``Mapping.feed_newest``). A failed write ends the
        take, as in ``_apply``."""
        if not self._into_take(lambda: self._take_newest(samples)):
            self.mapping.feed_newest(samples)

    def _into_take(self, write: Callable[[], None]) -> bool:
        """Run ``write`` (into the take's log and clock, which feeds the mapping) while recording:
        True when it did. A write that fails ends the take, marked incomplete, and gives False:
        the caller feeds the mapping itself, and the live face goes on."""
        if self._clock is None:
            return False
        try:
            write()
            return True
        except OSError as exc:
            self._end_take(str(exc.strerror or exc))
        except Exception as exc:  # noqa: BLE001 -- any failed write ends the take, not the face
            self._end_take(f"{type(exc).__name__}: {exc}")
        return False

    def _take_entry(self, entry: Sample | LogEvent) -> None:
        if isinstance(entry, Sample):
            self._recorder.sample(entry)
        else:
            self._recorder.event(entry)
        self._clock.apply(entry)

    def _take_newest(self, samples: list[Sample]) -> None:
        self._recorder.event(LogEvent(samples[0].t_ns, "newest", {"count": len(samples)}))
        self._recorder.samples(samples)
        self._clock.apply_newest(samples)

    def _end_take(self, why: str) -> None:
        """End the take now, marked incomplete with ``why`` (``record_error``)."""
        recorder, self._recorder, self._clock = self._recorder, None, None
        self.record_error = f"{recorder.folder}: recording stopped after {recorder.frames} frames: {why}"
        recorder.abandon(self.record_error)

    def _layered(self, now: int, pose: Pose):
        """The layered pass as shown: the base take where the take is now (its start before)."""
        return self.layer.merge(self._layer_frame(now), pose)

    def _layer_frame(self, now: int) -> int:
        if self._clock is None:
            return 0
        return max(0, (now - self._clock.t0_ns) * self.fps // 1_000_000_000)

    def layer_status(self, now_ns: int | None = None) -> str | None:
        """A layered pass as the cockpit says it (the base take, its frame now, what is armed);
        None when the session records no layered pass."""
        if self.layer is None:
            return None
        return self.layer.describe(self._layer_frame(time.monotonic_ns() if now_ns is None else now_ns))

    @property
    def states(self) -> dict[str, State]:
        return {name: d.state for name, d in self.devices.items()}

    # -- recording --------------------------------------------------------------------------

    @property
    def recording(self) -> bool:
        return self._recorder is not None

    @property
    def take_folder(self) -> Path | None:
        """The folder of the take being recorded (None when not recording)."""
        return None if self._recorder is None else Path(self._recorder.folder)

    def start_recording(self, now_ns: int | None = None):
        """Start a take under ``record_root`` (its first frame is at ``now_ns``, default now)."""
        if self._recorder is not None:
            raise RuntimeError("already recording")
        t0 = time.monotonic_ns() if now_ns is None else int(now_ns)
        hold_ns = self._hold_ns if self._held else None
        layer = None
        if self.layer is not None:  # shown and recorded from the base's start, each its own stream
            self.layer, layer = self.layer.restarted(), self.layer.restarted()
        extra = {"t0_ns": t0, "hold_ns": hold_ns, "mapping_state": self.mapping.snapshot(),
                 "wire": {name: d.wire_info() for name, d in self.devices.items()},
                 "layer": None if layer is None else layer.spec()}
        try:
            self._recorder = TakeRecorder(self.record_root, self.take_name, self.fps,
                                          mapping_path=self.mapping_path, devices=self.urls, extra=extra)
        except OSError as exc:
            raise TakeError(f"{self.record_root}: cannot make a take folder there: {exc.strerror or exc}") from exc
        self.record_error = None
        self._clock = TakeClock(self.mapping, self._recorder.frame, t0, self.fps, hold_ns=hold_ns, layer=layer,
                                encode_muscles=self.runtime.muscle_faps)
        return self._recorder.folder

    def stop_recording(self) -> Path:
        """Finish the take (frames up to the last ``frame()``); returns its folder."""
        if self._recorder is None:
            raise RuntimeError("not recording")
        recorder, self._recorder, self._clock = self._recorder, None, None
        if self.layer is not None:  # the next pass shows the base from its start again
            self.layer = self.layer.restarted()
        return recorder.close()

    # -- closing ----------------------------------------------------------------------------

    def close(self) -> None:
        """Finish any take and close every device (each one, even if another fails)."""
        try:
            if self._recorder is not None:
                self.stop_recording()
        finally:
            self._close_devices()

    def _close_devices(self) -> None:
        close_each(self.devices.values())

    def __enter__(self) -> LiveSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def close_each(things: Iterable) -> None:
    """Close each of ``things`` (devices, outputs), even if another fails; the first failure is
    raised after."""
    errors = []
    for thing in things:
        try:
            thing.close()
        except Exception as exc:  # noqa: BLE001 -- close the rest, then report
            errors.append(exc)
    if errors:
        raise errors[0]


# -- latency ----------------------------------------------------------------------------------

def ms_stats(values_ns: list[int]) -> dict:
    """Median and 99th percentile, in milliseconds (NaN when nothing was measured)."""
    if not values_ns:
        return {"median": float("nan"), "p99": float("nan")}
    ms = sorted(v / 1e6 for v in values_ns)
    return {"median": statistics.median(ms), "p99": ms[min(len(ms) - 1, int(np.ceil(0.99 * len(ms))) - 1)]}


def measure_latency(session: LiveSession, renderer, seconds: float = 3.0, outputs=()) -> dict:
    """Run the live loop for ``seconds``, rendering every frame offscreen, and time it.

    Every Sample is measured from its timestamp to the first frame that shows it:
    ``sample_to_drawn_ms`` until that frame is drawn and read back (``renderer.render``),
    ``sample_to_mesh_ms`` until its vertices and normals are ready, before drawing;
    ``frame_work_ms`` is a frame's own work from taking the Samples in to the mesh ready (its
    normals too unless the renderer's draw sums them: it sets ``session.normals``), and
    ``draw_ms`` its drawing and read-back: a Sample waits for the frame being drawn when it
    arrives, then for its own. The loop starts a frame as soon as a Sample is queued
    (``wait_for_input``), as a live loop free of a display's clock would. Samples queued before
    the loop starts (while the device was opened and the shaders compiled, up to 100 ms old)
    are taken in by a frame of their own, not timed (``samples_before``): they were 1.3% of a 3 s
    run, and all of its p99. Medians and 99th percentiles. The device's own transport (USB, the
    pty) comes before the Sample's timestamp and is not included. ``gl_renderer``, ``normals``
    (``cpu``, or ``draw`` where the renderer sums them) and ``rasteriser_cores`` (the cores a
    software rasteriser's threads were given, one each; none on a GPU) say what drew. ``outputs``
    (``puppet.view.liveoutput.LiveOutput``: the show server) get their turn before each frame and
    the frame after it is drawn, as in the live window.
    """
    session.normals = not renderer.gpu_normals
    if renderer.camera is None:
        renderer.aim(session.runtime.rest)
    renderer.render(session.runtime.rest, session.runtime.rest_normals)  # warm-up (shaders, buffers)
    before = session.frame().n_samples  # queued before the loop (while shaders compiled): not its latency
    drawn, mesh, work, draw = [], [], [], []
    frames = 0
    start = time.monotonic_ns()
    end = start + int(seconds * 1e9)
    while time.monotonic_ns() < end:
        session.wait_for_input(0.1)
        for output in outputs:
            output.service()
        f = session.frame()
        ready = time.monotonic_ns()
        renderer.render(f.vertices, f.normals)
        done = time.monotonic_ns()
        for output in outputs:
            output.publish(f.vertices)
        frames += 1
        draw.append(done - ready)
        if f.sample_ns:
            drawn.extend(done - t for t in f.sample_ns)
            mesh.extend(ready - t for t in f.sample_ns)
            work.append(ready - f.t_ns)
    elapsed = (time.monotonic_ns() - start) / 1e9
    return {"sample_to_drawn_ms": ms_stats(drawn), "sample_to_mesh_ms": ms_stats(mesh),
            "frame_work_ms": ms_stats(work), "draw_ms": ms_stats(draw), "fps": frames / elapsed if elapsed else 0.0,
            "frames": frames, "samples": len(drawn), "samples_before": before,
            "gl_renderer": str(renderer.ctx.info.get("GL_RENDERER", "")),
            "normals": "draw" if renderer.gpu_normals else "cpu",
            "rasteriser_cores": sorted(set(renderer.rasteriser_cores.values()))}
