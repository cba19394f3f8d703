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
``{"t_ns": ..., "event": "newest", "count": 340}`` (a flood: the loop took each channel's newest
value of the next ``count`` Samples, per frame of the take, rather than every one;
``puppet.live.takeclock``).
``read_take_log`` yields both, in order. Lines are written by a thread of the writer's own, in
order, and flushed batch by batch; a take makes them all reach the file before each frame.
"""

from __future__ import annotations

import collections
import json
import os
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from devices.base import Sample
from devices.samplelines import HEADER, SampleLogError, is_event, read_records, sample_from, sample_line

EVENTS = ("frame", "hold", "resume", "reset", "recentre", "trigger", "newest")


@dataclass(frozen=True)
class LogEvent:
    """Something besides a Sample that a take's log records (see the module docstring)."""

    t_ns: int
    kind: str
    data: dict[str, Any] = field(default_factory=dict)


class SampleLogWriter:
    """Appends Samples (and events) to a log, in order, from a writer thread of its own.

    ``write`` and ``event`` only queue the entry, so a live loop taking in thousands of readings
    a second spends no time on their JSON or the disk (a flush per line cost it 120 µs a
    reading); the thread writes what is queued and flushes after each batch. The queue holds at
    most ``QUEUE`` entries: past that the caller waits for the thread (memory stays flat, no
    entry is dropped). ``sync()`` returns once everything queued is on the file, flushed: a take
    calls it before each frame of its .fap, so the log on disk always holds every entry that
    decided the frames there. A write that failed is raised, as it was (an OSError stays one),
    by the next ``write``, ``event``, ``sync`` or ``close``."""

    QUEUE = 65_536

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._file: IO[str] = open(self.path, "w", encoding="utf-8")
        self._file.write(json.dumps(HEADER) + "\n")
        self._file.flush()
        self.count = 0  # Samples queued (each is written unless the file fails)
        self._queue: collections.deque[Sample | LogEvent] = collections.deque()
        self._queued = self._written = 0
        self._changed = threading.Condition()
        self._error: BaseException | None = None
        self._closing = False
        self._thread = threading.Thread(target=self._run, name=f"log {self.path.name}", daemon=True)
        self._thread.start()

    def write(self, sample: Sample) -> None:
        self._put(sample)
        self.count += 1

    def write_all(self, samples: list[Sample]) -> None:
        """``write`` each of ``samples``, queued together."""
        for start in range(0, len(samples), self.QUEUE):
            self._put_all(samples[start:start + self.QUEUE])
        self.count += len(samples)

    def event(self, event: LogEvent) -> None:
        self._put(event)

    def _put(self, entry: Sample | LogEvent) -> None:
        self._put_all((entry,))

    def _put_all(self, entries: Sequence[Sample | LogEvent]) -> None:
        """Queue ``entries`` (at most ``QUEUE``), first waiting for room if the thread is behind."""
        if self._error is not None:
            raise self._error
        if len(self._queue) + len(entries) > self.QUEUE:
            with self._changed:
                self._changed.notify_all()
                self._changed.wait_for(lambda: len(self._queue) + len(entries) <= self.QUEUE
                                       or self._error is not None)
            if self._error is not None:
                raise self._error
        was_empty = not self._queue
        self._queue.extend(entries)
        self._queued += len(entries)
        if was_empty:
            with self._changed:
                self._changed.notify_all()

    def sync(self) -> None:
        """Wait until every entry queued so far is written and flushed (raise its failure)."""
        target = self._queued
        with self._changed:
            self._changed.notify_all()
            self._changed.wait_for(lambda: self._written >= target or self._error is not None)
        if self._error is not None:
            raise self._error

    def _run(self) -> None:
        queue, lines = self._queue, []
        while True:
            with self._changed:
                self._changed.wait_for(lambda: queue or self._closing, 0.05)
                if not queue and self._closing:
                    return
            try:
                n = len(queue)
                for _ in range(n):
                    entry = queue.popleft()
                    lines.append(sample_line(entry) if isinstance(entry, Sample) else _event_line(entry))
                self._file.write("\n".join(lines) + "\n" if lines else "")
                lines.clear()
                self._file.flush()
            except BaseException as exc:  # noqa: BLE001 -- kept, and raised in the caller's thread
                with self._changed:
                    self._error = exc
                    self._changed.notify_all()
                return
            with self._changed:
                self._written += n
                self._changed.notify_all()

    def close(self) -> None:
        """Write what is queued, stop the thread and close the file (raise a failed write)."""
        with self._changed:
            self._closing = True
            self._changed.notify_all()
        self._thread.join()
        self._file.close()
        if self._error is not None:
            raise self._error

    def __enter__(self) -> SampleLogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _event_line(event: LogEvent) -> str:
    return json.dumps({"t_ns": event.t_ns, "event": event.kind, **event.data})


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
