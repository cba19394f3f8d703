"""MIDI controllers (fader boxes, knobs, keyboards) through mido and python-rtmidi.

``midi://nanoKONTROL2`` opens the first input port whose name contains the given text
(``?channel=N`` keeps one MIDI channel, 0-15; ``?cc14=0,1,7`` names the 14-bit controllers).
Messages become channels:

* control change ``n`` -> ``ccN``, 0..1 (value / 127);
* 14-bit controllers, only those named in ``cc14`` (many boxes use controllers 32-63 as buttons,
  so pairing is never guessed): controller ``n`` (0-31) then its LSB partner ``n + 32`` on the
  same MIDI channel gives ``ccN`` at full resolution, (MSB * 128 + LSB) / 16383;
* pitch bend -> ``pitchbend``, -1..1;
* notes -> ``noteN``, 1 while held (note on with velocity > 0), 0 on release: buttons;
* anything else (clock, sysex, aftertouch) is ignored.

The port opener is injected (``open_input``, mido's by default) so tests can feed real
``mido.Message`` objects without an ALSA sequencer; a port that fails to open or vanishes makes
the device ``LOST`` and it retries, like any other unplugged controller.

``MidiTwin`` is the wire twin (``devices.twin``): a ``MidiDevice`` opened from the logged URL on a
``MessagePort``, fed the messages that make each logged reading.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any
from urllib.parse import quote

import mido

from devices.base import Device, DeviceError, DeviceLost, Found, Url
from devices.twin import Twin

POLL = 0.005
WAIT = 0.03


def open_port(name: str) -> Any:
    """The first MIDI input port whose name contains ``name`` (OSError when there is none)."""
    names = input_names()
    matches = [n for n in names if name.lower() in n.lower()]
    if not matches:
        raise DeviceLost(f"no MIDI input port matching {name!r} (ports: {names})")
    return mido.open_input(matches[0])


class MidiDevice(Device):
    """Channels from a MIDI input port."""

    OPTIONS = frozenset({"channel", "cc14"})

    def __init__(self, name: str, port: str, channel: int | None = None, cc14: Iterable[int] = (),
                 open_input: Callable[[str], object] = open_port) -> None:
        super().__init__(name)
        if channel is not None and not 0 <= channel <= 15:
            raise DeviceError(f"{name}: MIDI channel {channel} (expected 0-15)")
        self.cc14 = frozenset(cc14)
        if any(not 0 <= c <= 31 for c in self.cc14):
            raise DeviceError(f"{name}: 14-bit controllers are 0-31, got {sorted(self.cc14)}")
        self.port_name, self.channel = port, channel
        self._open_input = open_input
        self._port: Any = None  # a mido input port while open
        self._msb: dict[tuple[int, int], int] = {}

    @classmethod
    def from_url(cls, url: Url, name: str, open_input: Callable[[str], object] = open_port) -> MidiDevice:
        cls.check_options(url)
        try:
            channel = url.options.get("channel")
            cc14 = [int(c) for c in url.options.get("cc14", "").split(",") if c]
            return cls(name, url.target.strip("/"), None if channel is None else int(channel), cc14, open_input)
        except ValueError as exc:
            raise DeviceError(f"midi URL: {exc}") from None

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
        out: list[Mapping[str, float]] = []
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
            return self._controller(message.channel, message.control, message.value)
        if message.type == "pitchwheel":
            return {"pitchbend": message.pitch / 8192 if message.pitch < 0 else message.pitch / 8191}
        if message.type in ("note_on", "note_off"):
            held = message.type == "note_on" and message.velocity > 0
            return {f"note{message.note}": 1.0 if held else 0.0}
        return None

    def _controller(self, channel: int, control: int, value: int) -> dict[str, float]:
        if control in self.cc14:
            self._msb[channel, control] = value
        elif control - 32 in self.cc14 and (channel, control - 32) in self._msb:
            msb = self._msb[channel, control - 32]
            return {f"cc{control - 32}": (msb * 128 + value) / 16383}
        return {f"cc{control}": value / 127}

    def _close(self) -> None:
        if self._port is not None:
            self._port.close()
            self._port = None


class MessagePort:
    """A MIDI input port fed in process (``send``): what a twin opens instead of a real port."""

    def __init__(self) -> None:
        self._messages: deque[mido.Message] = deque()
        self.closed = False

    def send(self, message: mido.Message) -> None:
        self._messages.append(message)

    def iter_pending(self) -> Iterator[mido.Message]:
        while self._messages:
            yield self._messages.popleft()

    def close(self) -> None:
        self.closed = True


class MidiTwin(Twin):
    """``midi://`` wires: the ``MidiDevice`` of the logged URL reading a ``MessagePort``, fed the
    ``mido.Message``s that make each logged reading (on the device's MIDI channel, or 0).

    ``ccN`` is a control change of ``round(value * 127)``; a 14-bit controller's value that is
    such a step goes as its MSB alone (what the adapter reads from an MSB), any other as the
    LSB, led by the MSB when the last one sent differs (the adapter then makes two Samples, the
    second the reading's); ``pitchbend`` a pitch wheel; ``noteN`` a note on (velocity 127) for
    a nonzero value, a note off for 0. Values are clamped to the message's range: what no
    message makes comes back different.
    """
    device: MidiDevice  # the adapter this twin feeds

    def __init__(self, device: MidiDevice, port: MessagePort, url: str) -> None:
        self.port = port
        self._msb: dict[int, int] = {}  # 14-bit controller -> the MSB last sent
        super().__init__(device, url)

    @classmethod
    def from_url(cls, url: str, name: str, wire_info: Mapping[str, Any]) -> MidiTwin:
        port = MessagePort()
        return cls(MidiDevice.from_url(Url.parse(url), name, open_input=lambda _name: port), port, url)

    def _put(self, values: Mapping[str, float]) -> int:
        if len(values) != 1:
            raise ValueError(f"a MIDI message sets one channel, not {len(values)}")
        [(key, value)] = values.items()
        messages = self._messages(key, float(value))
        for message in messages:
            self.port.send(message)
        return len(messages)

    def _messages(self, key: str, value: float) -> list[mido.Message]:
        channel = self.device.channel or 0
        if key == "pitchbend":
            pitch = round(value * (8192 if value < 0 else 8191))
            return [mido.Message("pitchwheel", channel=channel, pitch=_clamp(pitch, -8192, 8191))]
        if key.startswith("note") and key[4:].isdigit():
            kind = "note_on" if value else "note_off"
            return [mido.Message(kind, channel=channel, note=int(key[4:]), velocity=127 if value else 0)]
        if key.startswith("cc") and key[2:].isdigit():
            control = int(key[2:])
            step = _clamp(round(value * 127), 0, 127)
            if control not in self.device.cc14:
                return [mido.Message("control_change", channel=channel, control=control, value=step)]
            if step / 127 == value:
                self._msb[control] = step
                return [mido.Message("control_change", channel=channel, control=control, value=step)]
            msb, lsb = divmod(_clamp(round(value * 16383), 0, 16383), 128)
            lead = [] if self._msb.get(control) == msb else [
                mido.Message("control_change", channel=channel, control=control, value=msb)]
            self._msb[control] = msb
            return lead + [mido.Message("control_change", channel=channel, control=control + 32, value=lsb)]
        raise ValueError(f"no MIDI message sets a channel named {key!r}")


def _clamp(value: int, lo: int, hi: int) -> int:
    return lo if value < lo else hi if value > hi else value


ALSA_SEQUENCER = "/dev/snd/seq"
"""What MIDI needs on Linux: the ALSA sequencer's device (absent in many containers and VMs)."""


def input_names() -> list[str]:
    """The MIDI input ports there are now (mido's names). A machine with no MIDI system is an
    OSError saying so, not an unplugged port: no port was ever there (and ALSA's own complaint,
    printed straight to file descriptor 2, is kept off the terminal)."""
    try:
        with _quiet_stderr():
            names: list[str] = mido.get_input_names()
            return names
    except Exception as exc:  # rtmidi's own SystemError when the machine has no MIDI system
        detail = str(exc).splitlines()[0]
        if sys.platform.startswith("linux") and not Path(ALSA_SEQUENCER).exists():
            detail = f"no {ALSA_SEQUENCER}: load the ALSA sequencer, sudo modprobe snd-seq"
        raise OSError(f"no MIDI system ({detail})") from None


def discover() -> list[Found]:
    """The MIDI input ports there are now, as URLs."""
    return [Found("midi", f"midi://{quote(name, safe=' ')}", "MIDI input") for name in input_names()]

@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Silence what C libraries write to the process's stderr (file descriptor 2) meanwhile."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


DEVICE, TWIN = MidiDevice, MidiTwin
