"""The live pipeline under load, for ``puppet bench``: latency, a flood of input, a long take.

* ``latency``: the live session on the default face reading a slider box that runs in a process
  of its own (``PtyJoystick`` on a pseudo-terminal, 200 readings/s, read by pyserial as
  ``puppet live`` reads a port), every frame drawn and read back by a 640x480 offscreen renderer
  with the live window's settings (``session.measure_latency``): every Sample, from its
  timestamp to the first frame that shows it, mesh ready and frame drawn; medians and p99, over
  ``BOX_CYCLE_S`` (``puppet bench --quick``: 3 s).
* ``flood``: the same loop, recording a take, while the box (a process of its own, as in
  ``latency``) sends ``rate`` readings a second (COBS frames) for ``seconds``: frames per second
  against a baseline run in the same call, recording too, at 200 readings/s; the samples taken
  in; the readings the device took in while recording against those in the take's raw log
  (``readings_missing``: none, however far the loop falls behind); the process's resident
  memory over time (flat: nothing grows; and its peak); and the device queue's longest backlog
  (bounded by ``Device.QUEUE``). Past ``LiveSession.FLOOD`` readings a frame the loop maps each
  channel's newest reading per frame (``puppet.live.session``, *Floods*).
* ``long_take``: a take of ``take_seconds`` made at an accelerated clock -- the recorder and
  take clock, the parts that grow with a take's length, fed ``rate`` readings a second through
  the shipped mapping (its muscles written as FAPs) as fast as they go -- with the resident
  memory at checkpoints.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import tempfile
import time
from collections.abc import Iterator

import numpy as np

from devices import open_device
from devices.base import Sample, State
from devices.simulated_serial import sine_sliders
from puppet.fap.pose import Pose
from puppet.io.samplelog import LogEvent
from puppet.io.shipped import shipped_mapping
from puppet.io.takes import TakeRecorder, open_take
from puppet.live.mappingfile import load_mapping
from puppet.live.session import LiveSession, measure_latency
from puppet.live.takeclock import TakeClock, default_muscle_faps
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import Renderer

MAPPING = shipped_mapping("arduino_sliders")
BOX_CYCLE_S = 20.0
"""The slider box's six sines (0.25 to 1.0 Hz) come back to where they were every 20 s: a latency
run of one cycle sees every combination of its sliders (a frown with a blink costs the frame
more than the rest), where a run of a few seconds sees whichever part of it the run falls on."""
PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mb() -> float:
    """This process's resident memory, in MiB (Linux ``/proc``)."""
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * PAGE / 2**20


def _session(runtime: Runtime, url: str, root: str, extra: dict[str, str] | None = None) -> LiveSession:
    devices = {"box": open_device(url, "box"), **{name: open_device(u, name) for name, u in (extra or {}).items()}}
    session = LiveSession(MAPPING, face=runtime, devices=devices, record_root=root)
    deadline = time.monotonic() + 5
    while not (session.frame().states["box"] is State.OPEN and session.samples_fed):
        if time.monotonic() > deadline:
            session.close()
            raise RuntimeError(f"the simulated box ({url}) did not start sending")
        time.sleep(0.01)
    return session


def live_renderer(runtime: Runtime, size: tuple[int, int]) -> Renderer:
    """An offscreen renderer with the live window's settings (``render.choose_antialias``'s
    default for this GL, as ``puppet live`` uses), so the latency measured is what it draws."""
    from puppet.view.rendertake import aim_at_head

    face = runtime.face
    renderer = Renderer.for_face(face, width=size[0], height=size[1])
    aim_at_head(renderer, face, "front")
    return renderer


def latency(runtime: Runtime, seconds: float = BOX_CYCLE_S, size: tuple[int, int] = (640, 480)) -> dict:
    """Input-to-frame latency of the live loop (see the module docstring)."""
    with live_box(runtime, size) as (session, renderer):
        return measure_latency(session, renderer, seconds)


@contextlib.contextmanager
def live_box(runtime: Runtime, size: tuple[int, int],
             extra: dict[str, str] | None = None) -> Iterator[tuple[LiveSession, Renderer]]:
    """(session, renderer): the slider box sending ascii lines at 200 readings/s from a process
    of its own, a live session reading it once it sends (and the ``extra`` devices, name: URL,
    read beside it), and an offscreen renderer of ``size`` with the live window's settings; all
    closed on leaving."""
    with tempfile.TemporaryDirectory() as root, box_process(root, 200.0, "ascii") as url:
        session = _session(runtime, url, root, extra)
        renderer = live_renderer(runtime, size)
        try:
            yield session, renderer
        finally:
            renderer.release()
            session.close()


@contextlib.contextmanager
def box_process(root: str, rate: float, protocol: str) -> Iterator[str]:
    """The URL of a six-slider box sending ``rate`` readings a second in ``protocol`` on a pty
    under ``root``, from a process of its own, as a real device sends from outside the process
    reading it (so the process measured pays for reading the device, not for simulating it);
    stopped on leaving."""
    spawn = multiprocessing.get_context("spawn")  # a clean process: no GL or threads of ours forked
    link, stop = os.path.join(root, f"box-{protocol}-{rate:g}"), spawn.Event()
    box = spawn.Process(target=serve_joystick, args=(link, rate, stop, protocol), daemon=True)
    box.start()
    try:
        _wait_for(link, box)
        yield f"serial://{link}?protocol={protocol}"
    finally:
        stop.set()
        box.join(5)


def serve_joystick(link: str, rate: float, stop, protocol: str = "ascii") -> None:
    """A six-slider box sending ``protocol`` readings at ``rate`` on a pty behind ``link`` until
    ``stop`` is set: the external device of ``latency`` and ``flood``, run in a process of its own."""
    from devices.simulated_serial import PtyJoystick

    with PtyJoystick(protocol, rate, 6, link=link) as joystick:
        joystick.start()
        stop.wait()


def _wait_for(link: str, box) -> None:
    deadline = time.monotonic() + 30
    while not os.path.exists(link):
        if not box.is_alive() or time.monotonic() > deadline:
            raise RuntimeError(f"the slider box process did not start ({link})")
        time.sleep(0.02)


def _loop(session: LiveSession, renderer: Renderer, seconds: float) -> dict:
    """Run frames (drawn and read back) for ``seconds``; fps, samples/s, memory and backlog."""
    device = session.devices["box"]
    frames, fed, backlog, rss = 0, session.samples_fed, 0, [rss_mb()]
    start = last = time.perf_counter()
    while (now := time.perf_counter()) - start < seconds:
        backlog = max(backlog, device.backlog)
        f = session.frame()
        renderer.render(f.vertices, f.normals)
        frames += 1
        if now - last >= 1.0:
            rss.append(rss_mb())
            last = now
    elapsed = time.perf_counter() - start
    rss.append(rss_mb())
    return {"fps": frames / elapsed, "samples_s": (session.samples_fed - fed) / elapsed, "rss_mb": rss,
            "backlog_max": backlog, "dropped": device.counters.dropped}


def _taken(device) -> int:
    """Readings the device has read and no longer queues: taken by the loop, or lost to its queue."""
    read, queued = device.tally()
    return read - queued


def flood(runtime: Runtime, seconds: float = 60.0, rate: float = 10_000.0,
          size: tuple[int, int] = (320, 240)) -> dict:
    """The live loop, recording, under ``rate`` readings a second (see the module docstring)."""
    renderer = live_renderer(runtime, size)
    try:
        with tempfile.TemporaryDirectory() as root:
            baseline = _recorded(runtime, renderer, root, 200.0, min(5.0, seconds))
            loaded = _recorded(runtime, renderer, root, rate, seconds)
    finally:
        renderer.release()
    rss = loaded["rss_mb"]
    settled = rss[min(len(rss) - 1, 2):] or rss
    return {"seconds": seconds, "rate": rate, "baseline_fps": baseline["fps"], "fps": loaded["fps"],
            "fps_ratio": loaded["fps"] / baseline["fps"], "samples_s": loaded["samples_s"],
            "readings_sent": loaded["sent"], "readings_logged": loaded["logged"],
            "readings_missing": loaded["sent"] - loaded["logged"],
            "rss_start_mb": settled[0], "rss_end_mb": rss[-1], "rss_peak_mb": max(rss),
            "rss_growth_mb": rss[-1] - settled[0],
            "backlog_max": loaded["backlog_max"], "dropped": loaded["dropped"], "take_mb": loaded["take_mb"]}


def _recorded(runtime: Runtime, renderer: Renderer, root: str, rate: float, seconds: float) -> dict:
    """``_loop`` recording a take of the box (a process of its own) sending ``rate`` readings a
    second, COBS frames; with the readings the device took in while recording (``sent``), those
    in the take's raw log (``logged``) and the take's size."""
    with box_process(root, rate, "cobs") as url:
        session = _session(runtime, url, root)
        device = session.devices["box"]
        try:
            session.start_recording()
            before = _taken(device)
            result = _loop(session, renderer, seconds)
            sent = _taken(device) - before
            take = session.stop_recording()
        finally:
            session.close()
    logged = sum(1 for _ in open_take(take).samples())
    take_mb = sum(p.stat().st_size for p in take.iterdir()) / 2**20
    return {**result, "sent": sent, "logged": logged, "take_mb": take_mb}


def box_poses(seconds: float = BOX_CYCLE_S, rate: float = 200.0, fps: float = 190.0) -> list[Pose]:
    """The Poses a live loop drawing ``fps`` frames a second shows over ``seconds`` of the slider
    box of ``latency`` (``sine_sliders`` sending ``rate`` readings a second, through the shipped
    mapping, its filters and muscles included): that run's frame work without its pty, GL or
    clock, to time in CPU time (``tools/bench/bench_cpu.py``)."""
    mapping = load_mapping(MAPPING)
    signal = sine_sliders(6)
    step, frame = 1e9 / rate, 1e9 / fps
    poses, fed = [], 0
    for k in range(int(seconds * fps)):
        now = int(k * frame)
        while fed * step <= now:
            values = signal(fed * step / 1e9)
            mapping.feed(Sample(int(fed * step), "box", {f"ch{c}": v for c, v in enumerate(values)}))
            fed += 1
        poses.append(mapping.pose(now))
    return poses


def long_take(take_seconds: float = 3600.0, rate: float = 100.0, fps: int = 30, checkpoints: int = 6) -> dict:
    """A take of ``take_seconds`` at an accelerated clock; resident memory at each checkpoint."""
    mapping = load_mapping(MAPPING)
    rng = np.random.default_rng(7)
    step = int(1e9 / rate)
    total = int(take_seconds * rate)
    resident = []
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as root:
        recorder = TakeRecorder(root, "long", fps, mapping_path=MAPPING, devices=mapping.devices)
        clock = TakeClock(mapping, recorder.frame, 0, fps, encode_muscles=default_muscle_faps)
        values = rng.uniform(0, 1023, size=6)
        for i in range(total):
            values = np.clip(values + rng.normal(0, 8, size=6), 0, 1023)
            sample = Sample(i * step, "box", {f"ch{c}": float(v) for c, v in enumerate(values)})
            recorder.sample(sample)
            clock.apply(sample)
            if (i + 1) % (total // checkpoints) == 0:
                resident.append(rss_mb())
        end = LogEvent(total * step, "frame")
        recorder.event(end)
        clock.apply(end)
        folder = recorder.close()
        take_mb = sum(p.stat().st_size for p in folder.iterdir()) / 2**20
    return {"take_seconds": take_seconds, "frames": clock.frames, "samples": total,
            "wall_s": time.perf_counter() - start, "rss_mb": resident,
            "rss_growth_mb": resident[-1] - resident[0], "take_mb": take_mb}
