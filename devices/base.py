"""What every input device has in common: Samples, a reader thread, reconnection, a URL.

A device adapter (serial, HID, CAN, MIDI, OSC, simulated) implements three small methods --
``_open``, ``_read`` and ``_close`` -- in the spirit of python-can's ``BusABC``; this base class
runs them in a thread of their own, stamps every reading with ``time.monotonic_ns()`` as soon as
it returns, and keeps the Samples in a bounded queue that never grows (the oldest are dropped and
counted). When the hardware disappears (``_open`` raises ``OSError`` or ``DeviceLost``; ``_read``
raises anything at all, since an adapter bug must not end the thread either) the device closes,
reports ``LOST`` with the error and reopens with exponential backoff, while whatever consumes its
Samples simply sees none: the face holds its pose.
"""

from __future__ import annotations

import collections
import contextlib
import difflib
import enum
import errno
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qsl, urlsplit

import numpy as np


@dataclass(frozen=True)
class Sound:
    """A block of sound a reading was made from: 16-bit mono PCM at ``rate`` Hz, its first sample
    heard at ``start_ns`` (``time.monotonic_ns()``'s clock), and the state the device's analysis
    was in before it (``devices.voice.Voice.state``). A take writes the blocks to its WAV, and the
    first block's state to its metadata, so that the sound replays into the same readings."""

    pcm: np.ndarray
    rate: int
    start_ns: int
    state: Mapping[str, Any] | None = None


@dataclass(frozen=True)
class Sample:
    """Raw channel values read from one device at one moment (``time.monotonic_ns()``); an audio
    device's Samples also carry the ``sound`` they were analysed from (not compared, not logged:
    the take keeps it as a WAV)."""

    t_ns: int
    device: str
    values: Mapping[str, float]
    sound: Sound | None = field(default=None, compare=False, repr=False)


class DeviceError(RuntimeError):
    """The root of every error ``devices/`` raises on purpose; raised as itself for a device that
    cannot be opened as asked (bad URL or option, unknown backend, missing library). Each more
    particular error derives from it and keeps its built-in base (``DeviceLost`` is an OSError,
    ``DescriptorError`` and ``BadFrame`` ValueErrors), so callers can catch either."""


class DeviceLost(DeviceError, OSError):
    """The hardware went away while open (unplugged, port closed); the device will reopen."""


class State(enum.Enum):
    CLOSED = "closed"
    OPENING = "opening"
    OPEN = "open"
    LOST = "lost"


@dataclass
class Counters:
    """What a device has seen: samples, dropped samples, bad frames (and bad checksums among
    them), reconnections; an audio device also its overruns (sound lost because it was not read
    in time) and underruns (sound that came late)."""

    samples: int = 0
    dropped: int = 0
    bad_frames: int = 0
    bad_checksums: int = 0  # of the bad frames, those whose checksum failed (serial ascii lines)
    reconnects: int = 0
    overruns: int = 0
    underruns: int = 0
    last_error: str = ""


@dataclass(frozen=True)
class Url:
    """A device URL split into its parts: ``scheme://target?key=value&...``."""

    scheme: str
    target: str
    options: dict[str, str] = field(default_factory=dict)

    @classmethod
    def parse(cls, url: str) -> Url:
        parts = urlsplit(url)
        if not parts.scheme:
            raise DeviceError(f"device URL {url!r}: expected scheme://target, e.g. serial:///dev/ttyACM0")
        target = (parts.netloc + parts.path) if parts.netloc else parts.path
        return cls(parts.scheme, target, dict(parse_qsl(parts.query)))


PLAIN_REASONS = {errno.ENOENT: "port missing", errno.ENODEV: "not plugged in", errno.ENXIO: "not plugged in",
                 errno.EACCES: "permission denied", errno.EPERM: "permission denied",
                 errno.EBUSY: "busy (another program has it open)"}
"""What an ``OSError``'s errno means to someone plugging controllers in."""


def lost_reason(exc: BaseException) -> str:
    """Why a device is LOST, as ``counters.last_error`` keeps it and the live cockpit and
    ``puppet calibrate`` show it: the plain reason first (port missing, permission denied,
    unplugged, ...), then the adapter's own words."""
    plain: str | None
    if isinstance(exc, DeviceLost):
        plain = "unplugged"
    else:
        plain = PLAIN_REASONS.get(getattr(exc, "errno", -1))
    text = (exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)) or type(exc).__name__
    return f"{plain}: {text}" if plain else text


def closest_hint(word: str, choices: Iterable[str]) -> str:
    """``"; did you mean 'channel'?"`` for the choice nearest ``word`` ("" when none is near)."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""




@dataclass(frozen=True)
class Found:
    """One connectable device, as a backend's ``discover()`` finds it: its URL and what the
    system says about it."""

    kind: str
    url: str
    description: str


class Device(ABC):
    """An input device read in its own thread; iterate ``samples()`` or poll ``drain()``."""

    QUEUE = 4096
    BACKOFF = (0.05, 2.0)  # first and longest wait between reopen attempts, in seconds
    OPTIONS: frozenset[str] = frozenset()
    """The URL options (``?key=value``) this backend reads; any other is refused, when the URL is
    parsed and, through ``unknown_option``, when a mapping is loaded."""

    @classmethod
    def unknown_option(cls, url: Url, key: str) -> str | None:
        """Why ``key`` is not an option of this backend for ``url`` (None when it is one)."""
        if key in cls.OPTIONS:
            return None
        known = sorted(cls.OPTIONS)
        return (f"unknown option {key!r} for a {url.scheme}:// device: expected "
                f"{'one of ' + ', '.join(known) if known else 'no options'}{closest_hint(key, known)}")

    @classmethod
    def unknown_channel(cls, url: Url, channel: str) -> str | None:
        """Why ``channel`` cannot be a channel of this backend's device at ``url`` (None when it
        can be, or when only the hardware knows: the default); a mapping naming it is refused."""
        return None

    @classmethod
    def check_options(cls, url: Url) -> None:
        """DeviceError naming the first option ``url`` has that this backend does not read."""
        for key in url.options:
            problem = cls.unknown_option(url, key)
            if problem:
                raise DeviceError(f"device URL {url.scheme}://{url.target}: {problem}")

    @classmethod
    @abstractmethod
    def from_url(cls, url: Url, name: str) -> Device:
        """The device a parsed URL of this backend's scheme names, called ``name`` (not started);
        a URL it cannot use (an unknown option, a bad value) is a ``DeviceError`` naming it."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.url: str | None = None  # the URL it was opened by (``open_device``), for a take's record
        self.state = State.CLOSED
        self.counters = Counters()
        self._queue: collections.deque[Sample] = collections.deque(maxlen=self.QUEUE)
        self._ready = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.wake: threading.Event | None = None  # set with every Sample queued: one event can wake a loop reading many devices

    # -- what an adapter implements ------------------------------------------------------

    @abstractmethod
    def _open(self) -> None:
        """Open the hardware; raise OSError (or DeviceLost) if it is not there."""

    @abstractmethod
    def _read(self) -> Iterable[Mapping[str, float]]:
        """Wait briefly (well under a second) for input; return the channel readings that came."""

    @abstractmethod
    def _close(self) -> None:
        """Release the hardware; must not raise."""

    def wire_info(self) -> dict[str, Any]:
        """What a take must keep to rebuild this device's wire later (JSON-able; e.g. a HID
        report descriptor read from the hardware). Most devices are fully described by their
        URL and return ``{}``."""
        return {}

    # -- what callers use --------------------------------------------------------------------

    def start(self) -> Device:
        """Start the reader thread (it opens the device, and reopens it when it is lost)."""
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name=f"device {self.name}", daemon=True)
            self._thread.start()
        return self

    def close(self, timeout: float = 2.0) -> None:
        """Stop the thread promptly and release the hardware."""
        self._stop.set()
        with self._ready:
            self._ready.notify_all()
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                raise DeviceError(f"{self.name}: the reader did not stop within {timeout} s")
            self._thread = None
        self.state = State.CLOSED

    def __enter__(self) -> Device:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def backlog(self) -> int:
        """Samples read and waiting to be drained (at most ``QUEUE``)."""
        return len(self._queue)

    def tally(self) -> tuple[int, int]:
        """(Samples read so far, Samples of them still queued), read together: what a caller
        has taken (or lost to a full queue) is their difference, exactly."""
        with self._ready:
            return self.counters.samples, len(self._queue)

    def drain(self) -> list[Sample]:
        """Every Sample read since the last call, oldest first (never blocks)."""
        with self._ready:
            out = list(self._queue)
            self._queue.clear()
        return out

    def samples(self, timeout: float | None = None) -> Iterator[Sample]:
        """Samples as they arrive; ends after ``timeout`` seconds without one, or on close."""
        while not self._stop.is_set():
            with self._ready:
                if not self._queue and not self._ready.wait_for(
                        lambda: self._queue or self._stop.is_set(), timeout):
                    return
                batch = list(self._queue)
                self._queue.clear()
            yield from batch

    def wait_state(self, state: State, timeout: float = 5.0) -> bool:
        """Wait until the device reaches ``state``; False on timeout."""
        deadline = time.monotonic() + timeout
        while self.state != state:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.005)
        return True

    # -- the reader thread -----------------------------------------------------------------

    def _run(self) -> None:
        wait = self.BACKOFF[0]
        while not self._stop.is_set():
            self.state = State.OPENING
            try:
                self._open()
            except Exception as exc:  # noqa: BLE001 -- whatever the adapter raised: report, retry
                self._lost(exc)
                wait = self._back_off(wait)
                continue
            self.state = State.OPEN
            delivered = self.counters.samples
            try:
                self._pump()
            except Exception as exc:  # noqa: BLE001 -- any adapter failure: close, report, reopen
                self._lost(exc)
            finally:
                with contextlib.suppress(Exception):
                    self._close()
            # a device that fails before delivering anything waits longer each time
            wait = self.BACKOFF[0] if self.counters.samples > delivered else self._back_off(wait)
        self.state = State.CLOSED

    def _back_off(self, wait: float) -> float:
        """Wait (unless closing) and return the next, longer wait."""
        self._stop.wait(wait)
        return min(wait * 2, self.BACKOFF[1])

    def _pump(self) -> None:
        while not self._stop.is_set():
            readings = self._read()
            if readings:
                t_ns = time.monotonic_ns()
                self._push_all([Sample(t_ns, self.name, dict(values)) for values in readings])

    def _push(self, sample: Sample) -> None:
        self._push_all([sample])

    def _push_all(self, samples: list[Sample]) -> None:
        """Queue the Samples of one read together: one lock and one wake-up for the lot (a
        device sending thousands a second reads tens at a time)."""
        with self._ready:
            self.counters.dropped += max(0, len(self._queue) + len(samples) - self.QUEUE)
            self._queue.extend(samples)
            self.counters.samples += len(samples)
            self._ready.notify_all()
        if self.wake is not None:
            self.wake.set()

    def _lost(self, exc: BaseException) -> None:
        if self.state == State.OPEN:
            self.counters.reconnects += 1
        self.counters.last_error = lost_reason(exc)
        self.state = State.LOST
