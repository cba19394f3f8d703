"""MIDI messages (parsed by mido from raw bytes) become fader, 14-bit, pitch bend and note channels."""

from __future__ import annotations

import time
from pathlib import Path

import mido
import pytest

from devices import DeviceError, open_device
from devices.base import DeviceLost, State
from devices.midi_device import ALSA_SEQUENCER, MidiDevice


class FakePort:
    """Stands in for a mido input port: messages parsed by mido from the bytes a box would send."""

    def __init__(self) -> None:
        self.pending: list[mido.Message] = []
        self.closed = False
        self.vanished = False

    def send_bytes(self, *data: int) -> None:
        self.pending.append(mido.Message.from_bytes(list(data)))

    def iter_pending(self):
        if self.vanished:
            raise OSError("MIDI port vanished")
        messages, self.pending = self.pending, []
        return iter(messages)

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def box():
    port = FakePort()
    plugged = {"yes": True}

    def open_input(name: str) -> FakePort:
        if not plugged["yes"]:
            raise DeviceLost(f"no MIDI input port matching {name!r}")
        return port

    device = MidiDevice("faders", "nanoKONTROL2", cc14=[7], open_input=open_input).start()
    assert device.wait_state(State.OPEN, 2.0)
    yield device, port, plugged
    device.close()


def _values(device, n: int) -> list[dict]:
    got, deadline = [], time.monotonic() + 2.0
    while len(got) < n and time.monotonic() < deadline:
        got += [s.values for s in device.drain()]
        time.sleep(0.005)
    return got


def test_control_changes_pitch_bend_and_notes(box):
    device, port, _ = box
    port.send_bytes(0xB0, 64, 127)          # cc64 full
    port.send_bytes(0xE0, 0x7F, 0x7F)       # pitch bend full up
    port.send_bytes(0xE0, 0x00, 0x00)       # full down
    port.send_bytes(0x90, 36, 100)          # note on
    port.send_bytes(0x90, 36, 0)            # note on, velocity 0 = release
    port.send_bytes(0xF8)                   # clock: ignored
    assert _values(device, 5) == [{"cc64": 1.0}, {"pitchbend": 1.0}, {"pitchbend": -1.0},
                                  {"note36": 1.0}, {"note36": 0.0}]


def test_a_14_bit_controller_pair_reads_at_full_resolution(box):
    device, port, _ = box
    port.send_bytes(0xB0, 7, 0x40)          # MSB
    port.send_bytes(0xB0, 39, 0x01)         # its LSB (7 + 32)
    port.send_bytes(0xB0, 0, 100)           # a plain fader ...
    port.send_bytes(0xB0, 32, 127)          # ... and a button on 32: not a 14-bit pair (0 is not named)
    coarse, fine, fader, button = _values(device, 4)
    assert coarse == {"cc7": 0x40 / 127}
    assert fine == {"cc7": (0x40 * 128 + 1) / 16383}
    assert fader == {"cc0": 100 / 127} and button == {"cc32": 1.0}


def test_a_channel_filter_keeps_one_midi_channel():
    device = MidiDevice("box", "x", channel=2)
    assert device.reading(mido.Message("control_change", channel=1, control=1, value=5)) is None
    assert device.reading(mido.Message("control_change", channel=2, control=1, value=127)) == {"cc1": 1.0}


def test_a_midi_url_names_the_port_and_channel():
    device = open_device("midi://nanoKONTROL2?channel=3&cc14=0,1")
    assert isinstance(device, MidiDevice)
    assert (device.port_name, device.channel, device.cc14) == ("nanoKONTROL2", 3, {0, 1})
    with pytest.raises(DeviceError, match="channel 16"):
        open_device("midi://box?channel=16")


@pytest.mark.skipif(Path(ALSA_SEQUENCER).exists(), reason="this machine has a MIDI system (an ALSA sequencer)")
def test_with_no_midi_system_a_midi_device_says_so_quietly_not_unplugged(capfd):
    """A machine without an ALSA sequencer never had the port: the device is LOST with "no MIDI
    system" and what to load, not "unplugged", and ALSA's own complaints stay off the terminal."""
    device = open_device("midi://nanoKONTROL2", "faders").start()
    try:
        assert device.wait_state(State.LOST, 5)
        time.sleep(0.2)  # a retry or two
        reason = device.counters.last_error
    finally:
        device.close()
    assert reason.startswith("no MIDI system (no /dev/snd/seq") and "unplugged" not in reason
    assert "seq_hw.c" not in capfd.readouterr().err
