"""Every device backend keeps one contract, in the manner of python-can's back-to-back tests: it opens,
reads what its hardware sends, goes LOST with a reason when unplugged and reads again when plugged
back, closes promptly, and (where it has a wire) gives a reading back bit for bit through its twin.

Each backend has a harness below: its simulated hardware (a pseudo-terminal, the fake HID source,
python-can's virtual bus, an in-process MIDI port, loopback UDP, a sample log) and its plug, the
nearest thing to a cable it has. The tests are written once, for all of them.
"""

from __future__ import annotations

import importlib
import json
import time
import uuid
from collections.abc import Callable

import mido
import numpy as np
import pytest
from polling import wait_for
from pythonosc.udp_client import SimpleUDPClient

from devices import BACKENDS, DeviceError, backends, open_device, open_twin
from devices.audio_device import AudioDevice
from devices.base import Device, DeviceLost, State, Url
from devices.can_device import CanSignal, SignalDecoder
from devices.hid_device import HidDevice
from devices.midi_device import MessagePort, MidiDevice
from devices.simulated_audio import FakeMicrophone, FakeSoundDevice
from devices.simulated_can import EXTRA_ID, JOYSTICK_SIGNALS, CanJoystick
from devices.simulated_hid import FakeHidModule, gamepad, gamepad_report
from devices.simulated_serial import PtyJoystick
from devices.twin import Twin
from devices.voice import CHANNELS, Voice
from puppet.io.wavwriter import WavWriter


class Harness:
    """One backend's device on its simulated hardware. ``send`` makes the hardware send a reading
    and returns channels the device must read of it; ``unplug``/``replug`` pull and restore its
    plug (None where it has none). Its twin, opened from ``twin_url``, must carry each of
    ``readings`` (readings the adapter can produce) bit for bit; None: the backend has no wire."""

    scheme: str
    readings: list[dict[str, float]] | None = None
    twin_url: str = ""
    twin_wire: dict | None = None  # what a take keeps for the twin (a sound device: its recorded sound)
    unplug: Callable[[], None] | None = None
    replug: Callable[[], None] | None = None

    def device(self) -> Device:
        raise NotImplementedError

    def send(self) -> dict[str, float]:
        raise NotImplementedError

    def close(self) -> None:
        pass


class SerialHarness(Harness):
    scheme, readings, twin_url = "serial", [{"ch0": 512.0, "ch1": -3.25}], "serial:///dev/ttyACM0?protocol=ascii"

    def __init__(self) -> None:
        self.stick = PtyJoystick("cobs", rate=None, channels=2).start()
        self.unplug, self.replug = self.stick.unplug, self.stick.replug

    def device(self) -> Device:
        return open_device(f"serial://{self.stick.path}?protocol=cobs", "box")

    def send(self) -> dict[str, float]:
        assert self.stick.send([100, -200])
        return {"ch0": 100.0, "ch1": -200.0}

    def close(self) -> None:
        self.stick.close()


class SimHarness(Harness):
    scheme, readings, twin_url = "sim", [{"ch0": 7.0, "ch1": 1023.0}], "sim://joystick?protocol=slip&channels=2"

    def device(self) -> Device:
        self.dev = open_device("sim://joystick?protocol=ascii&rate=200&channels=2", "box")
        self.unplug, self.replug = self.dev.joystick.unplug, self.dev.joystick.replug
        return self.dev

    def send(self) -> dict[str, float]:
        return {}  # it sends by itself: any reading of its channels


class HidHarness(Harness):
    scheme, readings, twin_url = "hid", [{"knob": 1.0, "push": 1.0}], "hid://16c0:05df?fields=knob:0:8;push:8:1"

    def __init__(self) -> None:
        self.pad = gamepad()
        self.module = FakeHidModule(self.pad)
        self.unplug, self.replug = self.pad.unplug, self.pad.replug

    def device(self) -> Device:
        return HidDevice.from_url(Url.parse("hid://046d:c21d"), "pad", hid_module=self.module)

    def send(self) -> dict[str, float]:
        self.pad.feed(gamepad_report(y=32767))
        return {"Y": 1.0}


class CanHarness(Harness):
    """python-can's virtual bus has no cable to pull: the nearest thing is the device's bus
    object going away (shut down) under it; it comes back by itself."""

    scheme, twin_url = "can", f"can://virtual/twin?signals={JOYSTICK_SIGNALS}"
    readings = [SignalDecoder(map(CanSignal.parse, JOYSTICK_SIGNALS.split(";"))).decode(EXTRA_ID, bytes([0x35, 0x07, 0xA0, 0x80]))]

    def __init__(self) -> None:
        self.channel = f"contract-{uuid.uuid4().hex}"
        self.joystick = CanJoystick(self.channel)
        self.replug = lambda: None

    def device(self) -> Device:
        self.dev = open_device(f"can://virtual/{self.channel}?signals={JOYSTICK_SIGNALS}", "stick")
        self.unplug = lambda: self.dev.bus.shutdown()
        return self.dev

    def send(self) -> dict[str, float]:
        return dict(self.joystick.tick(1.0))

    def close(self) -> None:
        self.joystick.close()


class MidiHarness(Harness):
    """An in-process port stands in for the ALSA one (these machines have no sequencer); the plug
    is whether the port opener finds it."""

    scheme, readings, twin_url = "midi", [{"cc7": 1.0}, {"pitchbend": -1.0}], "midi://faders"

    def __init__(self) -> None:
        self.port, self.plugged = VanishingPort(), True

    def device(self) -> Device:
        def open_input(name: str) -> VanishingPort:
            if not self.plugged:
                raise DeviceLost(f"no MIDI input port matching {name!r}")
            return self.port

        def pull() -> None:
            self.plugged, self.port.vanished = False, True

        def restore() -> None:
            self.port, self.plugged = VanishingPort(), True

        self.unplug, self.replug = pull, restore
        return MidiDevice.from_url(Url.parse("midi://faders"), "faders", open_input=open_input)

    def send(self) -> dict[str, float]:
        self.port.send(mido.Message("control_change", control=1, value=127))
        return {"cc1": 1.0}


class VanishingPort(MessagePort):
    """An in-process MIDI port whose hardware can go away: reading it then raises, as mido's does."""

    vanished = False

    def iter_pending(self):
        if self.vanished:
            raise OSError("MIDI port vanished")
        return super().iter_pending()


class OscHarness(Harness):
    """Datagrams on loopback: UDP has no cable, so no plug to pull."""

    scheme, readings, twin_url = "osc", [{"fader/1": 0.25}], "osc://127.0.0.1:0"

    def device(self) -> Device:
        self.dev = open_device("osc://127.0.0.1:0", "phone")
        return self.dev

    def send(self) -> dict[str, float]:
        SimpleUDPClient(*self.dev.address).send_message("/fader/1", 0.5)
        return {"fader/1": 0.5}


class ReplayHarness(Harness):
    """A sample log played back: a file, with no plug and no wire (so no twin)."""

    scheme, twin_url = "replay", "replay:///take/samples.jsonl"

    def __init__(self, tmp_path) -> None:
        self.path = tmp_path / "samples.jsonl"
        lines = [{"facepuppet_samples": 1}, {"t_ns": 1, "device": "box", "values": {"ch0": 0.5}}]
        self.path.write_text("".join(json.dumps(line) + "\n" for line in lines))

    def device(self) -> Device:
        return open_device(f"replay://{self.path}?speed=0", "box")

    def send(self) -> dict[str, float]:
        return {"ch0": 0.5}


class SoundHarness(Harness):
    """A recording a microphone hears: a vowel. Its twin plays a take's recorded sound back
    through ``wav://``, so the readings it must carry are the analysis's of that sound."""

    def __init__(self, tmp_path) -> None:
        t = np.arange(48000) / 48000
        self.sound = np.round(8000 * np.sin(2 * np.pi * 220 * t) * (1 + np.sin(2 * np.pi * 3 * t))).astype(np.int16)
        self.path = tmp_path / "heard.wav"
        with WavWriter(self.path, 48000) as writer:
            writer.write(self.sound)
        voice = Voice(48000)
        self.readings = [voice(self.sound[k * 480:(k + 1) * 480]) for k in range(3)]
        self.twin_wire = {"sound_file": str(self.path), "rate": 48000, "block": 480, "gate": -45.0}

    def send(self) -> dict[str, float]:
        return dict.fromkeys(CHANNELS)  # it hears by itself: any reading of the voice's channels


class WavHarness(SoundHarness):
    """A sound file: no plug to pull."""

    scheme, twin_url = "wav", "wav://speech.wav"

    def device(self) -> Device:
        return open_device(f"wav://{self.path}?loop=1", "mic")


class AudioHarness(SoundHarness):
    """A microphone behind sounddevice's interface (``devices.simulated_audio``: these machines
    have no sound card); its plug is the fake microphone's."""

    scheme, twin_url = "audio", "audio://Headset"

    def device(self) -> Device:
        mic = FakeMicrophone("USB Headset Mic", self.sound)
        self.unplug, self.replug = mic.unplug, mic.replug
        return AudioDevice.from_url(Url.parse("audio://headset"), "mic", sd_module=FakeSoundDevice(mic))


class ApiHarness(Harness):
    """The control API's device has no hardware and no plug: a reading is pushed in by the server."""

    scheme, readings, twin_url = "api", [{"smile": 0.8, "brow": -0.25}], "api://"

    def device(self) -> Device:
        self.dev = open_device("api://", "api")
        return self.dev

    def send(self) -> dict[str, float]:
        self.dev.push({"smile": 0.5})
        return {"smile": 0.5}


class KeysHarness(Harness):
    """The live window's keys have no hardware and no plug: the window pushes each press and release."""

    scheme, readings, twin_url = "keys", [{"1": 1.0}, {"1": 0.0, "f12": 1.0}], "keys://"

    def device(self) -> Device:
        self.dev = open_device("keys://", "keys")
        return self.dev

    def send(self) -> dict[str, float]:
        self.dev.push({"a": 1.0})
        return {"a": 1.0}


HARNESSES = {"serial": SerialHarness, "sim": SimHarness, "hid": HidHarness, "can": CanHarness,
             "midi": MidiHarness, "osc": OscHarness, "replay": ReplayHarness, "wav": WavHarness,
             "audio": AudioHarness, "api": ApiHarness, "keys": KeysHarness}
NEEDS_FOLDER = ("replay", "wav", "audio")


def test_every_built_in_backend_is_in_the_contract():
    assert set(HARNESSES) == set(BACKENDS)


@pytest.fixture(params=sorted(HARNESSES))
def harness(request, tmp_path):
    made = HARNESSES[request.param](tmp_path) if request.param in NEEDS_FOLDER else HARNESSES[request.param]()
    yield made
    made.close()


@pytest.fixture
def device(harness):
    dev = harness.device()
    dev.BACKOFF = (0.01, 0.1)
    dev.start()
    assert dev.wait_state(State.OPEN, 3.0), dev.counters.last_error
    yield dev
    dev.close()


def _reads(device: Device, harness: Harness, timeout: float = 3.0) -> bool:
    """Whether what the hardware sends comes out of the device (for the sim, which sends by
    itself, any reading of its channels)."""
    deadline, got = time.monotonic() + timeout, {}
    while time.monotonic() < deadline:
        expected = harness.send() or {"ch0": None, "ch1": None}  # a device that sends by itself
        for sample in device.samples(timeout=0.2):
            got.update(sample.values)
            if all(name in got and value in (None, got[name]) for name, value in expected.items()):
                return True
    return False


def test_a_backend_module_declares_its_parts(harness):
    module = importlib.import_module(BACKENDS[harness.scheme])
    assert issubclass(module.DEVICE, Device) and callable(module.DEVICE.from_url)
    assert isinstance(module.DEVICE.OPTIONS, frozenset)
    twin = getattr(module, "TWIN", None)
    assert twin is None or issubclass(twin, Twin)
    assert callable(getattr(module, "discover", lambda: None))


def test_it_opens_and_reads_what_its_hardware_sends(device, harness):
    assert _reads(device, harness)
    assert device.counters.bad_frames == 0


def test_unplugged_it_is_lost_with_a_reason_and_plugged_back_it_reads_again(device, harness):
    if harness.unplug is None:
        pytest.skip(f"{harness.scheme}:// has no plug to pull ({type(harness).__doc__.split(':')[0]})")
    assert _reads(device, harness)
    harness.unplug()
    assert wait_for(lambda: device.counters.reconnects >= 1 or device.state is State.LOST, 3.0)
    assert device.counters.last_error
    harness.replug()
    assert device.wait_state(State.OPEN, 3.0), device.counters.last_error
    assert _reads(device, harness)
    assert device.counters.reconnects == 1


def test_it_closes_promptly(device):
    time.sleep(0.05)
    started = time.monotonic()
    device.close()
    assert time.monotonic() - started < 0.5
    assert device.state is State.CLOSED


def test_a_reading_goes_round_its_twin_bit_for_bit(harness):
    """Replaying a take through its devices re-encodes each reading into the backend's wire and
    reads it back with the real adapter (``devices.open_twin``); a backend with no wire says so."""
    if harness.readings is None:
        with pytest.raises(DeviceError, match="cannot be replayed through a device"):
            open_twin(harness.twin_url, "box")
        return
    with open_twin(harness.twin_url, "box", harness.twin_wire) as twin:
        for reading in harness.readings:
            got = twin.exchange(reading).values
            assert [repr(got[k]) for k in sorted(reading)] == [repr(reading[k]) for k in sorted(reading)]


def test_a_third_party_backend_joins_by_its_entry_point(tmp_path, monkeypatch):
    """An installed package adds a backend with an entry point in ``facepuppet.devices`` (as
    python-can's ``can.interface``): its scheme then opens like a built-in one. It cannot take
    over a built-in scheme."""
    (tmp_path / "knobs_backend.py").write_text(
        "from devices.base import Device\n"
        "class Knobs(Device):\n"
        "    @classmethod\n"
        "    def from_url(cls, url, name):\n"
        "        return cls(name)\n"
        "    def _open(self): pass\n"
        "    def _read(self): return [{'knob': 1.0}]\n"
        "    def _close(self): pass\n"
        "DEVICE = Knobs\n")
    info = tmp_path / "knobs-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: knobs\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[facepuppet.devices]\nknobs = knobs_backend\nserial = knobs_backend\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    backends.cache_clear()
    try:
        with pytest.warns(UserWarning, match="take over a built-in device scheme"):
            found = backends()
        assert found["knobs"] == "knobs_backend" and found["serial"] == BACKENDS["serial"]
        with open_device("knobs://box", "box") as device:
            assert next(device.samples(timeout=2.0)).values == {"knob": 1.0}
    finally:
        backends.cache_clear()
