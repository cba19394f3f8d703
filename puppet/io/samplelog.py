"""A take's raw log: every Sample of the take, and the events that decide what it records.

The Samples are JSON lines (``devices.samplelines``: the format the ``replay://`` device reads);
between them the log carries **events**, the things besides Samples that decide what a take
records, so that replaying the log reproduces its .fap exactly:
``{"t_ns": ..., "event": "frame"}`` (the recorder wrote its frames up to here),
``{"t_ns": ..., "event": "hold", "states": {"box": "lost"}}`` (a device went away: the pose is
held from ``t_ns``; the gap in the take), ``{"t_ns": ..., "event": "resume"}`` (every device is
back), ``{"t_ns": ..., "event": "reset"}`` (the performer asked for the neutral pose) and
``{"t_ns": ..., "event": "recentre", "centres": {"pad.X": 131.0}}`` (sticks re-centred) and
``{"t_ns": ..., "event": "trigger", "name": "smile", "action": "fire"}`` (a trigger pressed,
released or fired by name, as the control API does).
``read_take_log`` yields both, in order. Every line is written and flushed as it comes.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from devices.base import Sample
from devices.samplelines import HEADER, SampleLogError, is_event, read_records, sample_from, sample_line

EVENTS = ("frame", "hold", "resume", "reset", "recentre", "trigger")


@dataclass(frozen=True)
class LogEvent:
    """Something besides a Sample that a take's log records (see the module docstring)."""

    t_ns: int
    kind: str
    data: dict[str, Any] = field(default_factory=dict)


class SampleLogWriter:
    """Appends Samples (and events) to a log, one flushed line each."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._file: IO[str] = open(self.path, "w", encoding="utf-8")
        self._file.write(json.dumps(HEADER) + "\n")
        self.count = 0

    def write(self, sample: Sample) -> None:
        self._file.write(sample_line(sample) + "\n")
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


def read_take_log(path: str | os.PathLike[str]) -> Iterator[Sample | LogEvent]:
    """The Samples and events of a log, streamed in order; a bad line names the file and line
    (a partial last one warns)."""
    for where, data in read_records(path):
        yield _event(data, where) if is_event(data) else sample_from(data, where)  # type: ignore[arg-type]  # a dict


def _event(data: dict[str, Any], where: str) -> LogEvent:
    kind, t_ns = data.pop("event"), data.pop("t_ns", None)
    if kind not in EVENTS or not isinstance(t_ns, int):
        raise SampleLogError(f"{where}: expected an event {EVENTS} with an integer t_ns, found {kind!r} at {t_ns!r}")
    return LogEvent(t_ns, kind, data)
