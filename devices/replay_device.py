"""``replay://``: a raw sample log played back as a device.

``replay:///path/to/take/samples.jsonl?speed=1`` reads a log (``devices.samplelines``) and gives
its Samples again: with the original spacing between them (``speed`` > 0 scales it) or as fast as
the reader takes (``speed=0``), each stamped with the time of its replay; ``device=NAME`` keeps one
device's Samples. It has no wire, so no twin: the log is what a twin would replay.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator, Mapping
from pathlib import Path

from devices.base import Device, DeviceError, Sample, Url
from devices.samplelines import read_samples


class ReplayDevice(Device):
    """A device that plays a sample log back (see module docstring)."""

    OPTIONS = frozenset({"speed", "device"})

    def __init__(self, name: str, path: str | os.PathLike[str], speed: float = 1.0, device: str | None = None) -> None:
        super().__init__(name)
        if speed < 0:
            raise DeviceError(f"replay: speed must be >= 0, got {speed}")
        self.path, self.speed, self.only = Path(path), speed, device
        self._samples: Iterator[Sample] | None = None
        self._origin: tuple[int, int] | None = None  # (first log t_ns, replay start t_ns)
        self.finished = False

    @classmethod
    def from_url(cls, url: Url, name: str) -> ReplayDevice:
        cls.check_options(url)
        try:
            speed = float(url.options.get("speed", 1.0))
        except ValueError:
            raise DeviceError(f"replay URL: speed {url.options['speed']!r} is not a number") from None
        return cls(name, url.target, speed, url.options.get("device"))

    def _open(self) -> None:
        if not self.path.is_file():
            raise FileNotFoundError(f"{self.path}: no such sample log")
        if self._samples is None:
            self._samples = (s for s in read_samples(self.path) if self.only in (None, s.device))

    def _read(self) -> list[Mapping[str, float]]:
        sample = next(self._samples, None) if not self.finished else None  # type: ignore[arg-type]  # set by _open
        if sample is None:
            self.finished = True
            time.sleep(0.02)
            return []
        if self.speed > 0:
            self._wait_for(sample.t_ns)
        return [sample.values]

    def _wait_for(self, t_ns: int) -> None:
        now = time.monotonic_ns()
        if self._origin is None:
            self._origin = (t_ns, now)
        due = self._origin[1] + (t_ns - self._origin[0]) / self.speed
        while not self._stop.is_set():
            left = (due - time.monotonic_ns()) / 1e9
            if left <= 0:
                return
            time.sleep(min(left, 0.005))

    def _close(self) -> None:
        pass


DEVICE = ReplayDevice
