"""MIDI controllers (fader boxes, knobs, keyboards) through mido and python-rtmidi.

``midi://nanoKONTROL2`` opens the first input port whose name contains the given text
(``?channel=N`` keeps one MIDI channel, 0-15). Messages become channels:

* control change ``n`` -> ``ccN``, 0..1 (value / 127);
* 14-bit controllers: a controller 0-31 followed by its LSB partner (``n + 32``) gives ``ccN`` at
  full resolution, (MSB * 128 + LSB) / 16383; the LSB alone is never a channel of its own;
* pitch bend -> ``pitchbend``, -1..1;
* notes -> ``noteN``, 1 while held (note on with velocity > 0), 0 on release: buttons;
* anything else (clock, sysex, aftertouch) is ignored.

The port opener is injected (``open_input``, mido's by default) so tests can feed real
``mido.Message`` objects without an ALSA sequencer; a port that fails to open or vanishes makes
the device ``LOST`` and it retries, like any other unplugged controller.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping

import mido

from .base import Device, DeviceLost, Url

POLL = 0.005
WAIT = 0.03


def open_port(name: str):
    """The first MIDI input port whose name contains ``name`` (OSError when there is none)."""
    try:
        names = mido.get_input_names()
    except Exception as exc:  # rtmidi raises its own SystemError when there is no MIDI system
        raise DeviceLost(f"no MIDI system: {exc}") from None
    matches = [n for n in names if name.lower() in n.lower()]
    if not matches:
        raise DeviceLost(f"no MIDI input port matching {name!r} (ports: {names})")
    return mido.open_input(matches[0])


class MidiDevice(Device):
    """Channels from a MIDI input port."""

    def __init__(self, name: str, port: str, channel: int | None = None,
                 open_input: Callable[[str], object] = open_port) -> None:
        super().__init__(name)
        self.port_name, self.channel = port, channel
        self._open_input = open_input
        self._port = None
        self._msb: dict[int, int] = {}

    @classmethod
    def from_url(cls, url: Url, name: str) -> MidiDevice:
        channel = url.options.get("channel")
        return cls(name, url.target.strip("/"), None if channel is None else int(channel))

    def _open(self) -> None:
        self._port = self._open_input(self.port_name)
        self._msb.clear()

    def _read(self) -> list[Mapping[str, float]]:
        deadline = time.monotonic() + WAIT
        while True:
            messages = list(self._port.iter_pending())
            if messages or time.monotonic() > deadline:
                break
            time.sleep(POLL)
        out = []
        for message in messages:
            reading = self.reading(message)
            if reading:
                out.append(reading)
        return out

    def reading(self, message: mido.Message) -> dict[str, float] | None:
        """The channel one message sets, or None when it sets none."""
        if getattr(message, "channel", None) is not None and self.channel not in (None, message.channel):
            return None
        if message.type == "control_change":
            return self._controller(message.control, message.value)
        if message.type == "pitchwheel":
            return {"pitchbend": message.pitch / 8192 if message.pitch < 0 else message.pitch / 8191}
        if message.type in ("note_on", "note_off"):
            held = message.type == "note_on" and message.velocity > 0
            return {f"note{message.note}": 1.0 if held else 0.0}
        return None

    def _controller(self, control: int, value: int) -> dict[str, float] | None:
        if control < 32:
            self._msb[control] = value
            return {f"cc{control}": value / 127}
        if 32 <= control < 64 and control - 32 in self._msb:
            msb = self._msb[control - 32]
            return {f"cc{control - 32}": (msb * 128 + value) / 16383}
        return {f"cc{control}": value / 127}

    def _close(self) -> None:
        if self._port is not None:
            self._port.close()
            self._port = None
