"""Input side of ``puppet bench``: samples per second through each adapter and its mapping, and
how long a sample takes to reach a Pose.

Each adapter reads its own simulated device, as fast as that device can send, through the real
library (a pseudo-terminal and pyserial; UDP on loopback and python-osc; mido messages; the fake
``hid.device``; python-can's virtual bus), and the consumer loop of a live session takes what
arrived (``drain``), feeds it to the shipped mapping for that kind of controller and asks for the
Pose. Two runs per adapter:

* flat out: ``samples_s`` counts samples through adapter and mapping per second while the device
  sends as fast as it can (its latencies are queueing under overload, not reported);
* at 1,000 samples/s (a 1 kHz HID poll): ``latency`` is from each Sample's timestamp (taken at the
  read) to the Pose that includes it: queueing, feed and pose; median and p99.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator

import numpy as np

from devices import open_device
from devices.base import Device, State
from puppet.io.shipped import mappings_folder
from puppet.live.channels import Mapping
from puppet.live.mappingfile import load_mapping

MAPPINGS = mappings_folder()


def measure(device: Device, mapping: Mapping, seconds: float) -> dict:
    """Run the consumer loop on a started device for ``seconds``; samples/s and latencies."""
    if not device.wait_state(State.OPEN, 5.0):
        raise RuntimeError(f"{device.name}: did not open ({device.counters.last_error})")
    device.drain()
    latencies, count = [], 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        batch = device.drain()
        if not batch:
            time.sleep(0.0002)
            continue
        for sample in batch:
            mapping.feed(sample)
        mapping.pose()
        done = time.monotonic_ns()
        latencies += [done - s.t_ns for s in batch]
        count += len(batch)
    elapsed = time.perf_counter() - start
    ms = np.array(latencies) / 1e6 if latencies else np.array([np.nan])
    return {"samples_s": count / elapsed, "latency_median_ms": float(np.median(ms)),
            "latency_p99_ms": float(np.percentile(ms, 99)), "bad_frames": device.counters.bad_frames,
            "dropped": device.counters.dropped}


PACED = 1000.0  # samples per second for the latency run


def _serial(rate: float | None) -> Iterator[tuple[Device, Mapping]]:
    device = open_device(f"sim://joystick?protocol=cobs&rate={rate or 0:g}&channels=6", name="box")
    with device:
        yield device, load_mapping(MAPPINGS / "arduino_sliders.yaml")


def _osc(rate: float | None) -> Iterator[tuple[Device, Mapping]]:
    device = open_device("osc://127.0.0.1:0", name="phone")
    with device, _thread(lambda stop: _vmc_sender(device, stop, rate)):
        yield device, load_mapping(MAPPINGS / "arkit_osc.yaml")


def _vmc_sender(device: Device, stop: threading.Event, rate: float | None) -> None:
    from pythonosc.udp_client import SimpleUDPClient

    device.wait_state(State.OPEN, 5.0)
    client = SimpleUDPClient(*device.address)
    for i in _ticks(stop, rate):
        client.send_message("/VMC/Ext/Blend/Val", ["JawOpen", 0.5 + 0.5 * np.sin(i / 50)])
        client.send_message("/VMC/Ext/Blend/Apply", [])
        if rate is None and i % 64 == 0:
            time.sleep(0.0005)  # let the reader keep up with the socket buffer


def _ticks(stop: threading.Event, rate: float | None) -> Iterator[int]:
    """0, 1, 2, ... at ``rate`` per second (as fast as possible for None) until ``stop``."""
    i, start = 0, time.perf_counter()
    while not stop.is_set():
        if rate is not None:
            delay = start + i / rate - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        yield i
        i += 1


def _midi(rate: float | None) -> Iterator[tuple[Device, Mapping]]:
    import mido

    from devices.midi_device import MidiDevice

    pending: list = []
    lock = threading.Lock()

    class Port:
        def iter_pending(self):
            with lock:
                out = pending[:]
                pending.clear()
            return iter(out)

        def close(self) -> None:
            pass

    def send(stop: threading.Event) -> None:
        for i in _ticks(stop, rate):
            with lock:
                if len(pending) < 4096:
                    pending.append(mido.Message("control_change", control=i % 8, value=i % 128))

    device = MidiDevice("kontrol", "fake", open_input=lambda name: Port())
    with device, _thread(send):
        yield device, load_mapping(MAPPINGS / "midi_faders.yaml")


def _hid(rate: float | None) -> Iterator[tuple[Device, Mapping]]:
    from devices.hid_device import HidDevice
    from devices.simulated_hid import FakeHidModule, gamepad, gamepad_motion

    pad = gamepad(reports=gamepad_motion(), rate=rate)
    device = HidDevice("pad", 0x046D, 0xC21D, hid_module=FakeHidModule(pad))
    with device:
        yield device, load_mapping(MAPPINGS / "gamepad_hid.yaml")


def _can(rate: float | None) -> Iterator[tuple[Device, Mapping]]:
    from devices.simulated_can import CanJoystick

    mapping = load_mapping(MAPPINGS / "can_joystick.yaml")
    device = open_device(mapping.devices["stick"].replace("/vcan0", "/bench"), name="stick")
    joystick = CanJoystick(channel="bench", rate=20000.0 if rate is None else rate / 2)  # 2 frames a tick
    with device, joystick:
        yield device, mapping


@contextlib.contextmanager
def _thread(body: Callable[[threading.Event], None]) -> Iterator[None]:
    stop = threading.Event()
    thread = threading.Thread(target=body, args=(stop,), daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(2.0)


ADAPTERS = {"serial (cobs, pty)": _serial, "osc (VMC, loopback UDP)": _osc, "midi (mido)": _midi,
            "hid (fake hid.device)": _hid, "can (virtual bus)": _can}


def bench_inputs(seconds: float = 2.0) -> list[dict]:
    """One row per adapter (see module docstring); an adapter that cannot run says why."""
    rows = []
    for name, setup in ADAPTERS.items():
        try:
            with contextlib.contextmanager(setup)(None) as (device, mapping):
                flat = measure(device, mapping, seconds)
            with contextlib.contextmanager(setup)(PACED) as (device, mapping):
                paced = measure(device, mapping, seconds)
        except Exception as exc:  # noqa: BLE001 -- a missing library must not hide the others
            rows.append({"adapter": name, "error": f"{type(exc).__name__}: {exc}"})
            continue
        rows.append({"adapter": name, "samples_s": flat["samples_s"], "paced_samples_s": paced["samples_s"],
                     "latency_median_ms": paced["latency_median_ms"], "latency_p99_ms": paced["latency_p99_ms"],
                     "bad_frames": flat["bad_frames"] + paced["bad_frames"]})
    return rows
