"""A device sending faster than the live loop maps: the face keeps up with the newest readings,
the take's raw log keeps every one, and a calm device is mapped reading by reading as before."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from devices.base import Device, Sample, State
from puppet.io.takes import open_take
from puppet.live.mappingfile import load_mapping
from puppet.live.retake import retake
from puppet.live.session import LiveSession
from puppet.runtime.runtime import Runtime

MAPPING = Path(__file__).resolve().parents[1] / "mappings" / "arduino_sliders.yaml"


def reading(i: int) -> dict[str, float]:
    """Reading ``i`` of the flooding box: six sliders, each its own slow ramp."""
    return {f"ch{c}": float((37 * i + 101 * c) % 1000 + 10) for c in range(6)}


class Flood(Device):
    """Sends ``total`` readings, ``per_read`` at a time, as fast as the loop lets its queue
    take them (it waits while more than half the queue is waiting: the loop is what falls
    behind, never the device's own bounded queue), then nothing. ``per_read`` of 1 and a
    ``pause`` make it a calm device instead."""

    def __init__(self, total: int, per_read: int, pause: float = 0.0) -> None:
        super().__init__("box")
        self.total, self.per_read, self.pause = total, per_read, pause
        self.sent = 0
        self.done = threading.Event()

    @classmethod
    def from_url(cls, url, name):  # pragma: no cover - made directly
        raise NotImplementedError

    def _open(self) -> None:
        pass

    def _read(self):
        if self.sent >= self.total:
            self.done.set()
            time.sleep(0.01)
            return []
        while self.backlog > self.QUEUE // 2:
            time.sleep(0.001)
        if self.pause:
            time.sleep(self.pause)
        batch = [reading(i) for i in range(self.sent, min(self.total, self.sent + self.per_read))]
        self.sent += len(batch)
        return batch

    def _close(self) -> None:
        pass


@pytest.fixture(scope="module")
def runtime(face):
    return Runtime(face)


def _session(runtime, device, root) -> LiveSession:
    session = LiveSession(MAPPING, face=runtime, devices={"box": device}, record_root=root, fps=30)
    session.mapping.idle = None  # the channels alone
    return session


def _until_sent(session: LiveSession, device: Flood) -> list:
    """Frames until the device has sent everything and the loop has taken it all in."""
    frames = []
    deadline = time.monotonic() + 60
    while not (device.done.is_set() and device.backlog == 0 and session.samples_fed == device.total):
        assert time.monotonic() < deadline, "the loop did not take the flood in"
        frames.append(session.frame())
        time.sleep(0.002)
    return frames


def test_a_flood_keeps_every_reading_in_the_take_and_the_face_ends_at_the_newest(runtime, tmp_path):
    device = Flood(total=30_000, per_read=250)
    session = _session(runtime, device, tmp_path)
    try:
        assert device.wait_state(State.OPEN, 5.0)
        folder = session.start_recording()
        frames = _until_sent(session, device)
        last = session.frame()
        session.stop_recording()
    finally:
        session.close()
    assert max(f.n_samples for f in frames) > LiveSession.FLOOD  # it was a flood: the loop fell behind
    assert device.counters.dropped == 0
    take = open_take(folder)
    logged = [s.values for s in take.samples()]
    assert logged == [reading(i) for i in range(device.total)]  # every reading, in order
    assert take.meta["samples"] == device.total

    newest = reading(device.total - 1)
    assert {c.name: c.raw for c in session.mapping.channels()} == {f"box.{k}": v for k, v in newest.items()}
    settled = load_mapping(MAPPING)   # the newest readings, held: where the face comes to rest
    for k in range(60):
        held = Sample(last.newest_sample_ns + k * 1_000_000_000, "box", newest)
        settled.feed(held)
        session.mapping.feed(held)
    np.testing.assert_allclose(session.mapping.pose().fap, settled.pose().fap, atol=1e-6)

    again = retake(folder, tmp_path / "again.fap")  # the flood's runs replay the same way
    assert again.identical and again.frames == take.meta["frames"]


def test_a_calm_device_is_mapped_reading_by_reading(runtime, tmp_path):
    """Below a flood every reading steps the filters, as a mapping fed each one does."""
    device = Flood(total=300, per_read=1, pause=0.002)
    session = _session(runtime, device, tmp_path)
    try:
        assert device.wait_state(State.OPEN, 5.0)
        fed: list[Sample] = []
        mapping = load_mapping(MAPPING)
        mapping.idle = None
        deadline = time.monotonic() + 60
        while not (device.done.is_set() and session.samples_fed == device.total):
            assert time.monotonic() < deadline
            f = session.frame()
            assert f.n_samples <= LiveSession.FLOOD
            fed += [Sample(t, "box", reading(len(fed) + k)) for k, t in enumerate(f.sample_ns)]
            for sample in fed[len(fed) - f.n_samples:]:
                mapping.feed(sample)
            np.testing.assert_array_equal(f.pose.fap, mapping.pose(f.t_ns).fap)
            time.sleep(0.005)
    finally:
        session.close()


def test_a_held_input_filters_the_same_whether_stepped_per_reading_or_per_frame():
    """What stepping the filters once a frame keeps: a slider moved and held through a flood
    (10,000 readings a second, 30 frames a second) follows what the same readings fed one by one
    give -- the exponential filter (the blink) exactly, every frame, since it is exact for a held
    input at any spacing; the One Euro filters come to the same rest."""
    per_reading, per_frame = load_mapping(MAPPING), load_mapping(MAPPING)
    t, step = 1_000_000_000, 100_000
    start = Sample(t, "box", reading(0))
    per_reading.feed(start)
    per_frame.feed(start)
    held = reading(500)
    for frame in range(90):
        run = [Sample(t + (frame * 333 + k + 1) * step, "box", held) for k in range(333)]
        for sample in run:
            per_reading.feed(sample)
        per_frame.feed_newest(run)
        blink = [{c.name: c.value for c in m.channels()}["box.ch5"] for m in (per_reading, per_frame)]
        assert blink[1] == pytest.approx(blink[0], rel=1e-9, abs=1e-12), frame
    a = {c.name: c.value for c in per_reading.channels()}
    b = {c.name: c.value for c in per_frame.channels()}
    assert a.keys() == b.keys()
    for name, value in a.items():
        assert b[name] == pytest.approx(value, abs=1e-6), name


def test_a_button_pressed_and_released_inside_a_flood_still_toggles(tmp_path):
    """Buttons see every reading of a run: a press inside one frame's readings is not lost."""
    mapping_file = tmp_path / "button.yaml"
    mapping_file.write_text("devices:\n  box: {url: \"sim://joystick\"}\n"
                            "channels:\n  box.ch0: {min: 0, max: 1, button: {mode: toggle, threshold: 0.5}}\n"
                            "targets:\n  - {fap: open_jaw, source: box.ch0, range: [0, 500]}\n")
    mapping = load_mapping(mapping_file)
    run = [Sample(1000 + k, "box", {"ch0": 1.0 if k == 50 else 0.0}) for k in range(200)]
    mapping.feed_newest(run)
    assert mapping.pose().fap[2] == 500.0
