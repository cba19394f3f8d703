"""A serial joystick on a pseudo-terminal: real bytes through a real tty, read by ``SerialDevice``.

``PtyJoystick`` opens ``os.openpty()``, sets the slave side raw (no echo, no line editing) and
writes readings on the master side -- ascii lines, COBS or SLIP frames, made by the encoders of
``devices.serial_wire`` -- from a generated signal (smooth sine sliders by default) or a script, at
a given rate, in a thread of its own. Whatever opens the slave with pyserial sees an ordinary
serial port.

Stable path, unplug and replug
------------------------------
A new pseudo-terminal gets a new ``/dev/pts/N``, so the joystick publishes a **symlink at a path
that never changes** (``joystick.path``; a fresh temporary directory's ``joystick`` unless
``link=`` is given) pointing at the current slave (``joystick.tty``). Point the device at the
symlink: ``serial://<path>?protocol=...``.

* ``unplug()`` closes both ends of the pty and removes the symlink. A reader blocked on the slave
  gets EIO (pyserial raises ``SerialException``): ``SerialDevice`` reports ``LOST``; its reopen
  attempts fail (no such file) and back off -- exactly what a USB port that vanished does.
* ``replug()`` opens a new pty and points the symlink at it (atomically); the device's next reopen
  attempt finds it and samples flow again.

The joystick keeps its own descriptor of the slave open, so the tty exists while no reader has it
open. Writes never block: bytes wait in a small buffer (8 KiB) while the reader is slow, and when it
is full -- nobody reading, or unplugged -- whole readings are dropped (``dropped``), never half a
frame. (pyserial flushes what was queued in the tty when it opens a port, like a real port.)

Rates: ``rate`` readings a second, paced by the clock and written in batches when the thread wakes
late; ``rate=math.inf`` writes as fast as the reader takes (for throughput measurements);
``rate=None`` starts no thread: the test calls ``send(values)`` and ``write(raw_bytes)``.

``sim://joystick?protocol=ascii&rate=200&channels=6`` (``devices.sim_device``) is a serial
device that starts its own ``PtyJoystick`` and reads it: a serial device for demos with no
hardware. Options: ``protocol``, ``rate`` (0 = as fast as possible), ``channels`` (a count, or
names), ``format`` (i16/f32 for cobs and slip), ``style`` (csv, space or pairs for ascii),
``checksum`` (``nmea``: ascii lines end in ``*hh``, and the reader checks them), ``motion``
(``sines``, the default, or ``calibrate``: ``rest_then_sweep``, a hand doing what ``puppet
calibrate`` asks, with ``rest`` seconds at rest first, default 4), ``seed`` (its noise).
"""

from __future__ import annotations

import math
import os
import random
import select
import shutil
import tempfile
import threading
import time
import tty
from collections.abc import Callable, Iterable, Sequence
from typing import cast

from devices.serial_wire import STYLES, encode_reading, make_parser

PENDING_MAX = 8192      # bytes waiting for the reader before whole readings are dropped
MAX_BATCH = 0.1         # at most this many seconds of readings are caught up after a stall
FLOOD_BLOCK = 256       # readings per block written in flood mode

Signal = Callable[[float], Sequence[float]]


def sine_sliders(channels: int = 6, lo: float = 0.0, hi: float = 1023.0, integer: bool = True) -> Signal:
    """Smooth sliders: channel i is a sine between lo and hi at (0.25 + 0.15 i) Hz."""
    mid, amp = (lo + hi) / 2, (hi - lo) / 2
    freqs = [2 * math.pi * (0.25 + 0.15 * i) for i in range(channels)]

    def signal(t: float) -> list[float]:
        values = [mid + amp * math.sin(f * t + i) for i, f in enumerate(freqs)]
        return [float(round(v)) for v in values] if integer else values
    return signal


def rest_then_sweep(channels: int = 6, rest_seconds: float = 4.0, seed: int = 0) -> Signal:
    """A hand on a 10-bit joystick box doing what calibration asks: every control left at rest for
    ``rest_seconds``, then each swept end to end at its own pace, over and over.

    Like a real box read by an Arduino's ADC: each control rests a little off mid-scale (up to
    +-30 counts), its ends stop short of the rails (6-24 counts in, as potentiometers do), and
    every reading carries noise, Gaussian of 1.2 counts with a 2-3 count flick one time in a
    hundred, rounded to whole counts in 0..1023.
    """
    shape = random.Random(seed)
    rests = [512 + shape.uniform(-30, 30) for _ in range(channels)]
    lows = [shape.uniform(6, 24) for _ in range(channels)]
    highs = [1023 - shape.uniform(6, 24) for _ in range(channels)]
    periods = [2.0 + 0.37 * i for i in range(channels)]
    starts = [(rest - lo) / (hi - lo) / 2 for rest, lo, hi in zip(rests, lows, highs)]  # sweep from rest, upward
    noise = random.Random(seed + 1)

    def signal(t: float) -> list[float]:
        values = []
        for i in range(channels):
            if t < rest_seconds:
                value = rests[i]
            else:
                phase = ((t - rest_seconds) / periods[i] + starts[i]) % 1.0
                value = lows[i] + (highs[i] - lows[i]) * (1 - abs(2 * phase - 1))
            value += noise.gauss(0.0, 1.2)
            if noise.random() < 0.01:
                value += noise.choice((-3, -2, 2, 3))
            values.append(float(min(1023, max(0, round(value)))))
        return values
    return signal


class PtyJoystick:
    """A serial joystick on a pseudo-terminal, with a stable path and a plug to pull."""

    def __init__(self, protocol: str = "ascii", rate: float | None = 200.0, channels: int = 6, *,
                 fmt: str = "i16", style: str = "csv", names: Sequence[str] | None = None,
                 signal: Signal | Iterable[Sequence[float]] | None = None, link: str | None = None,
                 checksum: str = "none") -> None:
        make_parser(protocol, fmt=fmt, checksum=checksum)  # checks protocol, format and checksum
        if style not in STYLES:
            raise ValueError(f"style {style!r}: expected one of {sorted(STYLES)}")
        if rate is not None and not rate >= 0:
            raise ValueError(f"rate must be >= 0, not {rate}")
        self.protocol, self.fmt, self.style, self.checksum = protocol, fmt, style, checksum
        self.rate = rate or None
        self.names = tuple(names) if names else tuple(f"ch{i}" for i in range(channels))
        self.channels = len(self.names)
        if signal is None:
            signal = sine_sliders(self.channels, integer=(protocol == "ascii" or fmt == "i16"))
        self._signal = signal if callable(signal) else None
        self._origin = self._next = 0  # reading numbers: where the signal's time starts, the next to send
        self._script = None if callable(signal) else list(signal)
        self._own_dir = link is None
        self.path = link or os.path.join(tempfile.mkdtemp(prefix="pty-joystick-"), "joystick")
        self.tty: str | None = None
        self.sent = 0           # readings handed to the tty
        self.dropped = 0        # readings dropped (unplugged, or nobody reading)
        self._master: int | None = None
        self._slave: int | None = None
        self._pending = bytearray()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- the plug ---------------------------------------------------------------------------------

    @property
    def plugged(self) -> bool:
        return self._master is not None

    def start(self) -> PtyJoystick:
        """Plug in and start sending (when a rate was given)."""
        if not self.plugged:
            self.replug()
        if self._thread is None and self.rate is not None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="pty joystick", daemon=True)
            self._thread.start()
        return self

    def replug(self) -> None:
        """Open a new pseudo-terminal and point ``path`` at it."""
        with self._lock:
            self._unplug_locked()
            master, slave = os.openpty()
            tty.setraw(slave)
            os.set_blocking(master, False)
            self._master, self._slave, self.tty = master, slave, os.ttyname(slave)
            os.makedirs(os.path.dirname(os.path.abspath(self.path)), exist_ok=True)
            if os.path.lexists(self.path) and not os.path.islink(self.path):
                raise FileExistsError(f"{self.path} exists and is not a symlink: not replacing it")
            temporary = f"{self.path}.{os.getpid()}.new"
            if os.path.lexists(temporary):
                os.unlink(temporary)
            os.symlink(self.tty, temporary)
            os.replace(temporary, self.path)

    def unplug(self) -> None:
        """Close the pseudo-terminal (the reader sees the device lost) and remove ``path``."""
        with self._lock:
            self._unplug_locked()

    def _unplug_locked(self) -> None:
        if self._master is None:
            return
        for fd in (self._master, self._slave):
            try:
                os.close(fd)  # type: ignore[arg-type]  # both open while _master is
            except OSError:
                pass
        self._master = self._slave = None
        self._pending.clear()
        if os.path.islink(self.path) and os.readlink(self.path) == self.tty:
            os.unlink(self.path)

    def close(self) -> None:
        """Stop sending, unplug, and remove the temporary directory."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        self.unplug()
        if self._own_dir:
            shutil.rmtree(os.path.dirname(self.path), ignore_errors=True)

    def __enter__(self) -> PtyJoystick:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- sending ----------------------------------------------------------------------------------

    def encode(self, values: Sequence[float]) -> bytes:
        """One reading in this joystick's wire format."""
        return encode_reading(values, self.protocol, self.fmt, self.style, self.names, self.checksum)

    def send(self, values: Sequence[float]) -> bool:
        """Send one reading now; False if it was dropped."""
        return self._submit(self.encode(values), 1)

    def write(self, data: bytes) -> bool:
        """Send raw bytes (line noise, a hand-made frame); False if they were dropped."""
        return self._submit(bytes(data), 0)

    def _submit(self, data: bytes, readings: int) -> bool:
        with self._lock:
            if self._master is None or len(self._pending) + len(data) > PENDING_MAX:
                self.dropped += readings
                self._flush_locked()
                return False
            self._pending += data
            self.sent += readings
            self._flush_locked()
            return True

    def _flush_locked(self) -> None:
        if self._master is None or not self._pending:
            return
        try:
            written = os.write(self._master, self._pending)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        del self._pending[:written]

    def _readings(self, start: int, stop: int) -> list[Sequence[float]]:
        if self._script is not None:
            return self._script[start:stop]
        return [self._signal((i - self._origin) / self.rate)  # type: ignore[misc,operator]  # paced, no script
                for i in range(start, stop)]

    def restart_motion(self) -> None:
        """Start the signal over from now: a hand doing what calibration asks (``motion=calibrate``)
        rests again, then sweeps, as a performer does when told to."""
        self._origin = self._next

    def _run(self) -> None:
        rate = cast(float, self.rate)  # only a paced joystick (one with a rate) runs
        if math.isinf(rate):
            self._flood()
            return
        period, t0, k = 1.0 / rate, time.monotonic(), 0
        limit = max(1, int(rate * MAX_BATCH))
        while not self._stop.is_set():
            due = int((time.monotonic() - t0) * rate) + 1
            if self._script is not None:
                due = min(due, len(self._script))
                if k >= due:
                    return
            if due - k > limit:          # woke very late: skip what is too old to matter
                self.dropped += due - k - limit
                k = due - limit
            readings = self._readings(k, due)
            self._next = due
            if readings:
                self._submit(b"".join(map(self.encode, readings)), len(readings))
            else:
                with self._lock:
                    self._flush_locked()
            k = due
            self._stop.wait(max(0.0, t0 + due * period - time.monotonic()))

    def _flood(self) -> None:
        if self._script is not None:
            readings = self._script
        else:
            readings = [self._signal(i / 1000.0) for i in range(FLOOD_BLOCK)]  # type: ignore[misc]  # no script
        block = b"".join(map(self.encode, readings))
        while not self._stop.is_set():
            with self._lock:
                master = self._master
                if master is not None:
                    select.select([], [master], [], 0.005)
                    if len(self._pending) < PENDING_MAX:
                        self._pending += block
                        self.sent += len(readings)
                    self._flush_locked()
            if master is None:
                self._stop.wait(0.01)
