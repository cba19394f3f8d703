"""Takes on disk: numbered folders holding the .fap, the raw sample log and what made them.

A take is a folder ``NAME_001/`` (the next free number; created with ``mkdir``, which never
succeeds twice, so two recorders can never write into one take) with

* ``take.fap``: the Pose sampled at the take's frame rate (25, 30, 50 or 60 frames/s), written by
  ``FapWriter``: flushed every frame, its header count exact after every frame;
* ``samples.jsonl``: every raw Sample as it arrived (``devices.samplelog``), flushed per sample,
  so the take can be re-mapped later;
* ``take.json``: the metadata -- name, fps, start time (UTC, ISO 8601), the mapping's path and
  text, the devices' URLs, what the session adds to replay the take exactly (``t0_ns``: the
  clock of frame 0, ``mapping_state``: the mapping's state then, ``hold_ns``, ``wire``: each
  device's ``wire_info()``, ``layer``: the base take of a layered pass) and, once the recorder
  closes, the frame and sample counts. It is written when recording starts and rewritten
  (atomically) when it ends, so a take that crashed still says what it was; ``complete`` is true
  only once the recorder closed normally (a failed write leaves it false, with ``error``).

A killed recorder leaves a readable take: every complete frame and every complete sample line.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from devices.base import Sample
from devices.samplelog import LogEvent, SampleLogWriter, read_sample_log, read_take_log

from .errors import PuppetError
from .fapfile import FapStream, FapWriter, read_fap

FPS_CHOICES = (25, 30, 50, 60)
FAP_NAME, LOG_NAME, META_NAME = "take.fap", "samples.jsonl", "take.json"


class TakeError(PuppetError, ValueError):
    """A take that cannot be made or read; the message names the folder and the problem."""


def next_take_folder(root: str | os.PathLike, name: str) -> Path:
    """Create and return ``root/NAME_NNN`` with the next free number (never an existing one)."""
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name):
        raise TakeError(f"take name {name!r}: use letters, digits, '.', '_' and '-'")
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    taken = [int(m.group(1)) for p in root.iterdir() if (m := re.fullmatch(rf"{re.escape(name)}_(\d+)", p.name))]
    number = max(taken, default=0) + 1
    while True:
        folder = root / f"{name}_{number:03d}"
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            number += 1


class TakeRecorder:
    """Records one take: raw Samples as they come, Pose frames at the take's fps."""

    def __init__(self, root: str | os.PathLike, name: str, fps: int = 25, *,
                 mapping_path: str | os.PathLike | None = None, devices: Mapping[str, str] | None = None,
                 extra: Mapping[str, object] | None = None) -> None:
        if fps not in FPS_CHOICES:
            raise TakeError(f"take fps {fps}: choose one of {FPS_CHOICES}")
        self.folder = next_take_folder(root, name)
        self.fps = fps
        self.meta = {
            "name": name, "fps": fps, "started": _dt.datetime.now(_dt.timezone.utc).isoformat(),
            "mapping": None if mapping_path is None else str(mapping_path),
            "mapping_text": None if mapping_path is None else Path(mapping_path).read_text("utf-8"),
            "devices": dict(devices or {}), **dict(extra or {}), "frames": None, "samples": None,
            "complete": False, "error": None,
        }
        try:
            self._write_meta()
            self._fap = FapWriter(self.folder / FAP_NAME, fps, f"{name}_{self.folder.name[-3:]}")
            self._log = SampleLogWriter(self.folder / LOG_NAME)
        except OSError as exc:
            raise TakeError(f"{self.folder}: cannot start the take: {exc.strerror or exc}") from exc
        self.frames = 0

    def sample(self, sample: Sample) -> None:
        """Log one raw Sample (call for every Sample, in arrival order)."""
        self._log.write(sample)

    def event(self, event: LogEvent) -> None:
        """Log one event (hold, resume, reset, frame) in its place among the Samples."""
        self._log.event(event)

    def frame(self, fap: np.ndarray, viseme: tuple | None = None, expression: tuple | None = None) -> None:
        """Write one frame: 68 low-level FAP values (FAPU; FAP 1/2 columns ignored) and the blends."""
        write_pose(self._fap, fap, viseme, expression)
        self.frames += 1

    def close(self) -> Path:
        """Finish the take (final counts in its metadata, marked complete); returns its folder."""
        self._fap.close()
        self._log.close()
        self.meta.update(frames=self.frames, samples=self._log.count, complete=True)
        self._write_meta()
        return self.folder

    def abandon(self, reason: str) -> Path:
        """Stop after a failed write (disk full, folder gone): close what can be closed and say
        in the metadata, if it can still be written, that the take is incomplete and why. What
        reached the disk stays readable to its last complete frame and line."""
        for part in (self._fap, self._log):
            try:
                part.close()
            except OSError:
                pass
        self.meta.update(frames=self.frames, samples=self._log.count, complete=False, error=reason)
        try:
            self._write_meta()
        except OSError:
            pass  # take.json still says "complete": false from the start
        return self.folder

    def __enter__(self) -> TakeRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _write_meta(self) -> None:
        partial = self.folder / f".{META_NAME}.partial"
        partial.write_text(json.dumps(self.meta, indent=1) + "\n", "utf-8")
        partial.replace(self.folder / META_NAME)


def write_pose(writer: FapWriter, fap: np.ndarray, viseme: tuple | None = None,
               expression: tuple | None = None) -> None:
    """Write a Pose's values as one .fap frame: FAPs 3..68 always, FAP 1 / 2 when given."""
    mask = np.ones(68, dtype=bool)
    mask[:2] = viseme is not None, expression is not None
    writer.write_frame(np.asarray(fap, dtype=float), mask,
                       viseme=None if viseme is None else (*viseme[:3], 0),
                       expression=None if expression is None else (*expression[:4], 0, 0))


@dataclass
class Take:
    """A recorded take, read back."""

    folder: Path
    meta: dict

    @property
    def fap_path(self) -> Path:
        return self.folder / FAP_NAME

    @property
    def log_path(self) -> Path:
        return self.folder / LOG_NAME

    def stream(self) -> FapStream:
        return read_fap(self.fap_path)

    def samples(self) -> Iterator[Sample]:
        return read_sample_log(self.log_path)

    def entries(self) -> Iterator[Sample | LogEvent]:
        """The log's Samples and events, in order (what replay feeds a ``TakeClock``)."""
        return read_take_log(self.log_path)


def open_take(folder: str | os.PathLike) -> Take:
    """Read a take folder's metadata (its .fap and log are read on demand)."""
    folder = Path(folder)
    meta_path = folder / META_NAME
    if not meta_path.is_file():
        raise TakeError(f"{folder}: not a take (no {META_NAME})")
    try:
        meta = json.loads(meta_path.read_text("utf-8"))
    except json.JSONDecodeError as exc:
        raise TakeError(f"{meta_path}:{exc.lineno}: not valid JSON ({exc.msg})") from None
    return Take(folder, meta)


def take_fap(path: str | os.PathLike) -> Path:
    """The .fap of a take given as its folder or as the .fap itself."""
    path = Path(path)
    if path.is_dir():
        return open_take(path).fap_path
    if not path.exists():
        raise TakeError(f"{path}: no such take (expected a take folder or a .fap file)")
    return path
