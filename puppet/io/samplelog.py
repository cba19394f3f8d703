"""Raw sample logs: every Sample of a take, one JSON object per line, and their replay.

A line is ``{"t_ns": 123456789, "device": "box", "values": {"ch0": 512.0, "ch1": 300.0}}``:
the Sample exactly (JSON keeps floats to the last bit with ``repr``), one line each, written and
flushed as they come, so a killed recorder leaves every complete line readable (a last, partial
line is skipped with a warning). The first line may be a header ``{"facepuppet_samples": 1}``.

A take's log also carries **events**, the things besides Samples that decide what a take
records, so that replaying the log reproduces its .fap exactly:
``{"t_ns": ..., "event": "frame"}`` (the recorder wrote its frames up to here),
``{"t_ns": ..., "event": "hold", "states": {"box": "lost"}}`` (a device went away: the pose is
held from ``t_ns``; the gap in the take), ``{"t_ns": ..., "event": "resume"}`` (every device is
back), ``{"t_ns": ..., "event": "reset"}`` (the performer asked for the neutral pose) and
``{"t_ns": ..., "event": "recentre", "centres": {"pad.X": 131.0}}`` (sticks re-centred).
``read_take_log`` yields both, in order; ``read_sample_log`` only the Samples.

``ReplayDevice`` (``replay:///path/to/take.samples.jsonl?speed=1``) plays a log back as a device:
with the original spacing between samples (``speed`` > 0 scales it) or as fast as the reader
takes (``speed=0``), stamping each replayed Sample with the time of its replay; ``device=NAME``
keeps one device's samples.
"""

from __future__ import annotations

import json
import os
import time
import warnings
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from devices.base import Device, DeviceError, Sample, Url

MAX_LINE = 1 << 20  # characters: a sample of 52 ARKit channels is about 2,000
HEADER = {"facepuppet_samples": 1}


EVENTS = ("frame", "hold", "resume", "reset", "recentre")


class SampleLogError(DeviceError, ValueError):
    """A sample log line that is not a Sample or an event (names the file and line)."""


@dataclass(frozen=True)
class LogEvent:
    """Something besides a Sample that a take's log records (see the module docstring)."""

    t_ns: int
    kind: str
    data: dict = field(default_factory=dict)


class SampleLogWriter:
    """Appends Samples (and events) to a log, one flushed line each."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._file: IO[str] = open(self.path, "w", encoding="utf-8")
        self._file.write(json.dumps(HEADER) + "\n")
        self.count = 0

    def write(self, sample: Sample) -> None:
        line = {"t_ns": sample.t_ns, "device": sample.device, "values": dict(sample.values)}
        self._file.write(json.dumps(line) + "\n")
        self._file.flush()
        self.count += 1

    def event(self, event: LogEvent) -> None:
        self._file.write(json.dumps({"t_ns": event.t_ns, "event": event.kind, **event.data}) + "\n")
        self._file.flush()

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> SampleLogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_sample_log(path: str | os.PathLike) -> Iterator[Sample]:
    """The Samples of a log, streamed (events skipped)."""
    return (entry for entry in read_take_log(path) if isinstance(entry, Sample))


def read_take_log(path: str | os.PathLike) -> Iterator[Sample | LogEvent]:
    """The Samples and events of a log, streamed in order; a bad line names the file and line
    (a partial last one warns). A line longer than ``MAX_LINE`` characters is refused unread."""
    with open(path, encoding="utf-8") as file:
        number, text = 0, file.readline(MAX_LINE + 1)
        while text:
            number += 1
            if len(text) > MAX_LINE:
                raise SampleLogError(f"{path}:{number}: a line of more than {MAX_LINE:,} characters, "
                                     "expected one JSON sample")
            following = file.readline(MAX_LINE + 1)
            try:
                data = json.loads(text)
            except (json.JSONDecodeError, RecursionError):
                if not following and not text.endswith("\n"):
                    warnings.warn(f"{path}:{number}: the last line is incomplete (the recorder stopped "
                                  "mid-line); skipped", stacklevel=2)
                    return
                raise SampleLogError(f"{path}:{number}: expected a JSON sample, found {text[:60]!r}") from None
            if data != HEADER:
                yield _event(data, f"{path}:{number}") if isinstance(data, dict) and "event" in data \
                    else _sample(data, f"{path}:{number}")
            text = following


def _event(data: dict, where: str) -> LogEvent:
    kind, t_ns = data.pop("event"), data.pop("t_ns", None)
    if kind not in EVENTS or not isinstance(t_ns, int):
        raise SampleLogError(f"{where}: expected an event {EVENTS} with an integer t_ns, found {kind!r} at {t_ns!r}")
    return LogEvent(t_ns, kind, data)


def _sample(data: object, where: str) -> Sample:
    if not (isinstance(data, dict) and isinstance(data.get("t_ns"), int) and isinstance(data.get("device"), str)
            and isinstance(data.get("values"), dict)):
        raise SampleLogError(f"{where}: expected {{\"t_ns\": int, \"device\": str, \"values\": {{...}}}}, "
                             f"found {data!r:.80}")
    values = data["values"]
    try:
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values.values()):
            return Sample(data["t_ns"], data["device"], {str(k): float(v) for k, v in values.items()})
    except OverflowError:
        pass
    raise SampleLogError(f"{where}: expected numbers as values, found {values!r:.80}")


class ReplayDevice(Device):
    """A device that plays a sample log back (see module docstring)."""

    OPTIONS = frozenset({"speed", "device"})

    def __init__(self, name: str, path: str | os.PathLike, speed: float = 1.0, device: str | None = None) -> None:
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
            self._samples = (s for s in read_sample_log(self.path) if self.only in (None, s.device))

    def _read(self) -> list[Mapping[str, float]]:
        sample = next(self._samples, None) if not self.finished else None
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
