"""Channels the program itself hands in: the live window's keys, the control API.

A ``PushedDevice`` has no hardware: whoever holds it calls ``push({"1": 1.0})`` (the window on a
key press, the API server on a message) and the reader thread turns each reading into a Sample,
stamped when it is taken off the inbox, exactly as a serial line is stamped when it is read. So a
pushed reading goes through the mapping, the take's raw log and a replay like any other device's.

Readings are checked where they are pushed: channel names are short strings, values finite
numbers; anything else is a ``ValueError`` naming the device and the channel, and nothing is
queued. The inbox is bounded (``INBOX``): a caller that pushes faster than the loop drains loses
the oldest readings, counted in ``counters.dropped``, and the live loop never waits.

``PushedTwin`` is the wire twin (``devices.twin``): a fresh device of the same class, pushed each
logged reading.
"""

from __future__ import annotations

import collections
import math
import threading
from collections.abc import Mapping
from typing import Any

from devices.base import Device, Url
from devices.twin import Twin

INBOX = 1024
"""Readings waiting for the reader thread, at most."""

MAX_CHANNEL = 64
"""The longest channel name a pushed reading may carry, in characters."""

WAIT = 0.05
"""How long the reader waits for a reading before looking whether it should stop, in seconds."""


class PushedDevice(Device):
    """A device whose readings are pushed in-process (``push``) rather than read from hardware."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self._inbox: collections.deque[dict[str, float]] = collections.deque(maxlen=INBOX)
        self._arrived = threading.Condition()

    @classmethod
    def from_url(cls, url: Url, name: str) -> PushedDevice:
        cls.check_options(url)
        return cls(name)

    def push(self, values: Mapping[str, float]) -> None:
        """Queue one reading (channel -> value); ValueError naming what is wrong, nothing queued."""
        reading = checked_reading(self.name, values)
        with self._arrived:
            if len(self._inbox) == self._inbox.maxlen:
                self.counters.dropped += 1
            self._inbox.append(reading)
            self._arrived.notify()

    def _open(self) -> None:
        pass

    def _read(self) -> list[dict[str, float]]:
        with self._arrived:
            if not self._inbox:
                self._arrived.wait(WAIT)
            readings = list(self._inbox)
            self._inbox.clear()
        return readings

    def _close(self) -> None:
        pass


def checked_reading(device: str, values: Mapping[str, float]) -> dict[str, float]:
    """``values`` as a reading: a non-empty mapping of short channel names to finite floats."""
    if not isinstance(values, Mapping) or not values:
        raise ValueError(f"{device}: a reading is a non-empty mapping of channel -> number, got {values!r:.80}")
    reading = {}
    for channel, value in values.items():
        if not isinstance(channel, str) or not 0 < len(channel) <= MAX_CHANNEL:
            raise ValueError(f"{device}: channel names are strings of 1-{MAX_CHANNEL} characters, "
                             f"got {channel!r:.80}")
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ValueError(f"{device}: channel {channel!r} needs a finite number, got {value!r:.80}")
        reading[channel] = float(value)
    return reading


class PushedTwin(Twin):
    """A pushed device's twin: a fresh device of the same class, pushed each logged reading."""
    device: PushedDevice  # the adapter this twin feeds

    DEVICE: type[PushedDevice] = PushedDevice

    @classmethod
    def from_url(cls, url: str, name: str, wire_info: Mapping[str, Any]) -> PushedTwin:
        return cls(cls.DEVICE.from_url(Url.parse(url), name), url)

    def _put(self, values: Mapping[str, float]) -> int:
        self.device.push(values)
        return 1
