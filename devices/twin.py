"""Wire twins: a logged device's wire, simulated, so a take can be replayed through the real adapter.

A take keeps every raw Sample a device produced, its URL and its ``wire_info()``. A ``Twin``
rebuilds that device's wire from them: the REAL adapter class, opened with the URL's options on a
simulated transport (a pseudo-terminal, fake HID hardware, a fresh python-can virtual channel, an
in-process MIDI port, loopback UDP), and an encoder that turns one logged reading back into the
bytes or messages the hardware would have sent. ``exchange`` sends a reading and returns the
adapter's Sample of it, checked bit for bit against what was sent: replaying a take this way tests
the adapters' decoding against everything that was ever recorded, and reproduces the take exactly.

A backend module names its twin ``TWIN``, and ``devices.open_twin(url, name, wire_info)`` picks it
by the URL's scheme, like ``open_device``. A URL with no wire (``replay://``, anything that is not
a device URL) has no twin: ``open_twin`` raises ``DeviceError`` naming it.
"""

from __future__ import annotations

import struct
import time
from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any, Self

from devices.base import Device, DeviceError, Sample, State

OPEN_TIMEOUT = 5.0  # seconds the adapter may take to open its simulated transport
POLL = 0.001        # seconds between looks at the adapter's queue


class Twin(ABC):
    """A logged device's wire, simulated: the real adapter (``self.device``, named as logged,
    started) reading a simulated transport, and an encoder that puts one logged reading on it.

    A subclass builds its transport and adapter, then calls ``Twin.__init__``, which starts the
    adapter and waits until it is open (so nothing sent is lost to an opening port). It implements
    ``_put``; it overrides ``close`` to release its transport after ``super().close()``.
    """

    def __init__(self, device: Device, url: str) -> None:
        self.device, self.url = device, url
        device.start()
        if not device.wait_state(State.OPEN, OPEN_TIMEOUT):
            error = device.counters.last_error
            self.close()
            raise DeviceError(f"{device.name}: the {url!r} adapter did not open on its twin's "
                              f"simulated wire: {error or 'timed out'}")

    @classmethod
    @abstractmethod
    def from_url(cls, url: str, name: str, wire_info: Mapping[str, Any]) -> Twin:
        """The twin of the device ``url`` (a valid URL of this twin's scheme) named ``name``,
        with the take's ``wire_info``."""

    @abstractmethod
    def _put(self, values: Mapping[str, float]) -> int:
        """Encode one reading onto the wire; return how many Samples the adapter makes of it (the
        last is the reading's; a MIDI 14-bit value may need its MSB message first). Raise
        ValueError (or an ArithmeticError) when the wire cannot carry the reading at all."""

    def send(self, values: Mapping[str, float]) -> None:
        """Encode one logged reading onto the wire."""
        self._send(values)

    def _send(self, values: Mapping[str, float]) -> int:
        if not values:
            raise DeviceError(f"{self.device.name}: an empty reading has no wire form")
        try:
            return self._put(values)
        except (ValueError, ArithmeticError) as exc:
            raise DeviceError(f"{self.device.name}: the {self.url!r} wire cannot carry "
                              f"{dict(values)}: {exc}") from None

    def exchange(self, values: Mapping[str, float], timeout: float = 2.0) -> Sample:
        """Send one reading and return the adapter's Sample of it. Raises DeviceError naming the
        device when none comes within ``timeout`` seconds, when the adapter rejects the wire form
        as a bad frame, or when the decoded values are not bit-for-bit the ones sent."""
        device = self.device
        stale = device.drain()
        if stale:
            raise DeviceError(f"{device.name}: the {self.url!r} adapter made Samples no reading was "
                              f"sent for: {[s.values for s in stale]}")
        bad = device.counters.bad_frames
        expected = self._send(values)
        got: list[Sample] = []
        deadline = time.monotonic() + timeout
        while True:
            got += device.drain()
            if len(got) >= expected:
                break
            if device.counters.bad_frames != bad:
                raise DeviceError(f"{device.name}: the {self.url!r} adapter rejected {dict(values)} "
                                  f"as a bad frame ({device.counters.last_error or 'no detail'})")
            if time.monotonic() > deadline:
                raise DeviceError(f"{device.name}: no Sample from the {self.url!r} adapter within "
                                  f"{timeout} s of sending {dict(values)}")
            time.sleep(POLL)
        if len(got) > expected:
            raise DeviceError(f"{device.name}: the {self.url!r} adapter made {len(got)} Samples of "
                              f"{dict(values)}, not {expected}: {[s.values for s in got]}")
        sample = got[-1]
        mismatch = differences(values, sample.values)
        if mismatch:
            raise DeviceError(f"{device.name}: the {self.url!r} wire does not carry the reading "
                              f"exactly: {mismatch}")
        return sample

    def close(self) -> None:
        """Stop the adapter and release the simulated transport (subclasses extend this)."""
        self.device.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def differences(sent: Mapping[str, float], got: Mapping[str, float]) -> str:
    """How two readings differ, channel by channel, bit for bit ('' when they are identical)."""
    out = []
    for name in sorted(set(sent) | set(got), key=str):
        if name not in got:
            out.append(f"channel {name!r}: sent {sent[name]!r}, got nothing")
        elif name not in sent:
            out.append(f"channel {name!r}: sent nothing, got {got[name]!r}")
        elif _bits(sent[name]) != _bits(got[name]):
            out.append(f"channel {name!r}: sent {sent[name]!r}, got {got[name]!r}")
    return "; ".join(out)


def _bits(value: float) -> bytes:
    return struct.pack("<d", value)


__all__ = ["Twin", "differences"]
