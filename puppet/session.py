"""The live session: devices in, a deformed face out, once per frame, with an optional take.

``LiveSession(mapping_path)`` loads the mapping, opens every device it names (``open_device``;
``devices=`` replaces some or all of them by name, for tests) and starts their reader threads.
``session.frame()`` is one turn of the live loop:

1. drain every device (``Device.drain`` never blocks and empties the queue, so nothing queued
   grows however slowly the loop runs), merging the devices' Samples in timestamp order;
2. feed each Sample to the mapping (and, while recording, to the take's raw log; frame ticks
   that fall before a Sample are written first, see *Recording*);
3. take the mapping's Pose at ``now`` and deform the face into buffers allocated once
   (``Frame.vertices`` / ``Frame.normals`` *are* those buffers: copy them to keep a frame).

Holding the pose
    While every device is OPEN the Pose is taken at ``now``, so smoothing settles between
    samples. While any device is not OPEN (LOST, or OPENING between reconnection attempts) the
    pose time is frozen at the last frame taken with every device open: the lost device's
    channels (no new samples) give exactly the values of that frame, so the face holds still
    instead of drifting on filter previews; other devices' new samples still come through at
    their filtered values. When the device is back (OPEN) the clock runs again.

Recording
    ``start_recording()`` opens a ``TakeRecorder``; tick k of the take is at
    ``t0 + k / fps`` (t0: the clock when recording started). Each frame writes the Pose for
    every tick that has passed since the last written one, evaluated *between* the Samples
    (ticks before a Sample's timestamp are written before that Sample is fed), so the .fap has
    exactly ``fps`` frames per second of take time whatever the loop rate, and a slow loop
    still writes the poses the performer made rather than repeating the latest one.

Muscles
    ``Pose.muscles`` is carried in the Frame but not drawn: the runtime has FAP drivers only
    (``Runtime.fap_controls``); muscle targets do nothing to the mesh yet.

``measure_latency(session, renderer, seconds)`` times input-to-frame latency: from the newest
Sample's timestamp (``time.monotonic_ns()`` right after the device's read returned) to the mesh
being ready, and to the frame drawn and read back (``renderer.render``).
"""

from __future__ import annotations

import heapq
import os
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from devices import Device, State, open_device

from .mapping import Pose, load_mapping
from .runtime import Runtime


@dataclass
class Frame:
    """One frame of the live loop. ``vertices`` and ``normals`` are the session's buffers,
    overwritten by the next frame; ``newest_sample_ns`` is the newest Sample ever fed (None before
    any); ``n_samples`` how many Samples this frame fed."""

    vertices: np.ndarray
    normals: np.ndarray
    pose: Pose
    t_ns: int
    newest_sample_ns: int | None
    states: dict[str, State] = field(default_factory=dict)
    n_samples: int = 0


class LiveSession:
    """Devices -> mapping -> face runtime, one ``frame()`` at a time; optionally recording a take."""

    def __init__(self, mapping_path: str | os.PathLike, *, face=None,
                 devices: dict[str, Device] | None = None, record_root: str | os.PathLike | None = None,
                 take_name: str = "take", fps: int = 30) -> None:
        self.mapping_path = Path(mapping_path)
        self.mapping = load_mapping(mapping_path)  # checked before anything opens
        if isinstance(face, Runtime):
            self.runtime = face
        else:
            if face is None:
                from .face import load_face

                face = load_face()
            self.runtime = Runtime(face)
        self.record_root = Path(record_root) if record_root is not None else Path("takes")
        self.take_name, self.fps = take_name, fps

        overrides = dict(devices or {})
        for name, device in overrides.items():
            if device.name != name:
                raise ValueError(f"device override {name!r}: the device is named {device.name!r}, so its "
                                 f"Samples would not reach the mapping's {name!r} channels")
        self.devices: dict[str, Device] = {}
        self.urls: dict[str, str] = {}
        try:
            for name, url in self.mapping.devices.items():
                if name in overrides:
                    self.devices[name] = overrides.pop(name)
                    self.urls[name] = f"override:{type(self.devices[name]).__name__}"
                else:
                    self.devices[name] = open_device(url, name)
                    self.urls[name] = url
            for name, device in overrides.items():  # extra devices: read (and logged), not mapped
                self.devices[name] = device
                self.urls[name] = f"override:{type(device).__name__}"
            for device in self.devices.values():
                device.start()
        except BaseException:
            self._close_devices()
            raise

        self._vertices = np.empty_like(self.runtime.rest)
        self._normals = np.empty_like(self.runtime.rest)
        self._hold_ns: int | None = None    # pose time of the last frame with every device open
        self._last_pose_ns: int | None = None
        self._have_mesh = False
        self.newest_sample_ns: int | None = None
        self.samples_fed = 0
        self.frames = 0
        self._recorder = None
        self._t0 = 0
        self._tick = 0

    # -- the live loop ----------------------------------------------------------------------

    def frame(self, now_ns: int | None = None) -> Frame:
        """Drain, map, deform: one frame at ``now_ns`` (default: ``time.monotonic_ns()``)."""
        states = {name: d.state for name, d in self.devices.items()}
        batches = [d.drain() for d in self.devices.values()]
        now = time.monotonic_ns() if now_ns is None else int(now_ns)
        if all(s is State.OPEN for s in states.values()):
            pose_ns = now
            self._hold_ns = now
        else:
            pose_ns = now if self._hold_ns is None else min(now, self._hold_ns)

        if len(batches) == 1:
            samples = batches[0]
        else:
            samples = list(heapq.merge(*batches, key=lambda s: s.t_ns))
        recorder = self._recorder
        for sample in samples:
            if recorder is not None:
                self._write_ticks(sample.t_ns)
                recorder.sample(sample)
            self.mapping.feed(sample)
            if self.newest_sample_ns is None or sample.t_ns > self.newest_sample_ns:
                self.newest_sample_ns = sample.t_ns
        self.samples_fed += len(samples)
        if recorder is not None:
            self._write_ticks(now + 1)  # every tick at or before now

        pose = self.mapping.pose(pose_ns)
        if samples or pose_ns != self._last_pose_ns or not self._have_mesh:
            d, motions = self.runtime.fap_controls(pose.fap, viseme=pose.viseme, expression=pose.expression)
            self.runtime.deform_with_normals(d, motions, out=self._vertices, normals_out=self._normals)
            self._have_mesh = True
        # else: nothing changed since the last frame (a held pose): the buffers already hold it
        self._last_pose_ns = pose_ns
        self.frames += 1
        return Frame(self._vertices, self._normals, pose, now, self.newest_sample_ns, states, len(samples))

    @property
    def states(self) -> dict[str, State]:
        return {name: d.state for name, d in self.devices.items()}

    # -- recording --------------------------------------------------------------------------

    @property
    def recording(self) -> bool:
        return self._recorder is not None

    def start_recording(self, now_ns: int | None = None):
        """Start a take under ``record_root`` (its first frame is at ``now_ns``, default now)."""
        if self._recorder is not None:
            raise RuntimeError("already recording")
        from .takes import TakeRecorder

        self._recorder = TakeRecorder(self.record_root, self.take_name, self.fps,
                                      mapping_path=self.mapping_path, devices=self.urls)
        self._t0 = time.monotonic_ns() if now_ns is None else int(now_ns)
        self._tick = 0
        return self._recorder.folder

    def stop_recording(self) -> Path:
        """Finish the take (frames up to the last ``frame()``); returns its folder."""
        if self._recorder is None:
            raise RuntimeError("not recording")
        recorder, self._recorder = self._recorder, None
        return recorder.close()

    def _tick_ns(self, k: int) -> int:
        return self._t0 + (k * 1_000_000_000) // self.fps

    def _write_ticks(self, before_ns: int) -> None:
        """Write the pose of every tick strictly before ``before_ns`` not yet written."""
        recorder = self._recorder
        while (t := self._tick_ns(self._tick)) < before_ns:
            if self._hold_ns is not None and any(d.state is not State.OPEN for d in self.devices.values()):
                t = min(t, self._hold_ns)
            pose = self.mapping.pose(t)
            recorder.frame(pose.fap, pose.viseme, pose.expression)
            self._tick += 1

    # -- closing ----------------------------------------------------------------------------

    def close(self) -> None:
        """Finish any take and close every device (each one, even if another fails)."""
        try:
            if self._recorder is not None:
                self.stop_recording()
        finally:
            self._close_devices()

    def _close_devices(self) -> None:
        errors = []
        for device in self.devices.values():
            try:
                device.close()
            except Exception as exc:  # noqa: BLE001 -- close the rest, then report
                errors.append(exc)
        if errors:
            raise errors[0]

    def __enter__(self) -> LiveSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- latency ----------------------------------------------------------------------------------

def _ms_stats(values_ns: list[int], prefix: str) -> dict:
    if not values_ns:
        return {f"{prefix}_median_ms": float("nan"), f"{prefix}_p99_ms": float("nan")}
    ms = sorted(v / 1e6 for v in values_ns)
    p99 = ms[min(len(ms) - 1, int(np.ceil(0.99 * len(ms))) - 1)]
    return {f"{prefix}_median_ms": statistics.median(ms), f"{prefix}_p99_ms": p99}


def measure_latency(session: LiveSession, renderer, seconds: float = 3.0) -> dict:
    """Run the live loop for ``seconds``, rendering every frame offscreen, and time it.

    Only frames that took in at least one new Sample are measured (a frame with none would time
    how long the input has been still, not latency). ``latency``: newest Sample's timestamp ->
    frame drawn and read back (``renderer.render``); ``mesh``: newest Sample -> vertices and
    normals ready, before drawing. The device's own transport (USB, the pty) comes before the
    Sample's timestamp and is not included.
    """
    if renderer.camera is None:
        renderer.frame(session.runtime.rest)
    renderer.render(session.runtime.rest, session.runtime.rest_normals)  # warm-up (shaders, buffers)
    latency, mesh = [], []
    frames = 0
    start = time.monotonic_ns()
    end = start + int(seconds * 1e9)
    while time.monotonic_ns() < end:
        f = session.frame()
        ready = time.monotonic_ns()
        renderer.render(f.vertices, f.normals)
        done = time.monotonic_ns()
        frames += 1
        if f.n_samples and f.newest_sample_ns is not None:
            mesh.append(ready - f.newest_sample_ns)
            latency.append(done - f.newest_sample_ns)
    elapsed = (time.monotonic_ns() - start) / 1e9
    return {"frames": frames, "measured": len(latency), "fps": frames / elapsed if elapsed else 0.0,
            **_ms_stats(latency, "latency"), **_ms_stats(mesh, "mesh")}
