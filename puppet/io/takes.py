"""Takes on disk: numbered folders holding the .fap, the raw sample log and what made them.

A take is a folder ``NAME_001/`` (the next free number; created with ``mkdir``, which never
succeeds twice, so two recorders can never write into one take) with

* ``take.fap``: the Pose sampled at the take's frame rate (25, 30, 50 or 60 frames/s), written by
  ``FapWriter``: flushed every frame, its header count exact after every frame;
* ``samples.jsonl``: every raw Sample as it arrived (``puppet.io.samplelog``), written by a thread
  of its own (the live loop only queues them) and all on the file before each frame of the .fap,
  so the take can be re-mapped later;
* ``take.wav`` (and ``take.NAME.wav`` for a second audio device NAME): the sound each audio
  device heard while recording, block by block (``puppet.io.wavwriter``: readable up to the last
  block after a kill); ``take.json``'s ``sound`` says, per device, its file, rate, where its first
  frame falls on the Samples' clock (``first_ns``, against ``t0_ns``: frame 0 of the .fap) and the
  analysis's state before it (so the sound replays through ``wav://`` into the same readings);
* ``take.json``: the metadata -- name, fps, start time (UTC, ISO 8601), the mapping's path and
  text, the devices' URLs, what the session adds to replay the take exactly (``t0_ns``: the
  clock of frame 0, ``mapping_state``: the mapping's state then, ``hold_ns``, ``wire``: each
  device's ``wire_info()``, ``layer``: the base take of a layered pass) and, once the recorder
  closes, the frame and sample counts. It is written when recording starts and rewritten
  (atomically) when it ends, so a take that crashed still says what it was; ``complete`` is true
  only once the recorder closed normally (a failed write leaves it false, with ``error``).

A killed recorder leaves a readable take: every complete frame and every complete sample line.

Reading a take trusts nothing in it: ``open_take`` checks ``take.json`` against ``META_TYPES``
(each key may be missing, as in older takes, but never of another type), and a missing, binary,
truncated or garbled part is a ``TakeError`` naming the file and what was wrong. A folder with an
intact ``take.fap`` and no ``take.json`` still plays and renders (``take_fap`` warns).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import os
import re
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from devices.base import Sample
from devices.samplelines import read_samples
from devices.voice import json_state
from puppet.errors import PuppetError
from puppet.io.fapfile import FapStream, FapWriter, read_fap
from puppet.io.samplelog import LogEvent, SampleLogWriter, read_take_log
from puppet.io.wavwriter import WavWriter

FPS_CHOICES = (25, 30, 50, 60)
FAP_NAME, LOG_NAME, META_NAME, SOUND_NAME = "take.fap", "samples.jsonl", "take.json", "take.wav"
SOUND_FILE = re.compile(r"take(\.[A-Za-z_][A-Za-z0-9_-]*)?\.wav")
MAX_META_BYTES = 64 << 20


class TakeError(PuppetError, ValueError):
    """A take that cannot be made or read; the message names the folder and the problem."""


def check_take_name(name: str) -> str:
    """``name`` if it can name takes (``NAME_001``, ...); a TakeError saying what it may hold."""
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name):
        raise TakeError(f"take name {name!r}: use letters, digits, '.', '_' and '-'")
    return name


def next_take_folder(root: str | os.PathLike[str], name: str) -> Path:
    """Create and return ``root/NAME_NNN`` with the next free number (never an existing one)."""
    check_take_name(name)
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


def exact_take_folder(folder: Path) -> Path:
    """``folder`` made for a take (an empty one taken as it is); a TakeError if it holds anything."""
    if folder.is_dir() and any(folder.iterdir()):
        raise TakeError(f"{folder}: the folder holds files already; give a new or empty folder for the take")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TakeError(f"{folder}: cannot make a take folder there: {exc.strerror or exc}") from None
    return folder


class TakeRecorder:
    """Records one take: raw Samples as they come, Pose frames at the take's fps."""

    def __init__(self, root: str | os.PathLike[str], name: str, fps: int = 25, *,
                 mapping_path: str | os.PathLike[str] | None = None, devices: Mapping[str, str] | None = None,
                 extra: Mapping[str, object] | None = None, exact: bool = False) -> None:
        if fps not in FPS_CHOICES:
            raise TakeError(f"take fps {fps}: choose one of {FPS_CHOICES}")
        self.folder = exact_take_folder(Path(root) / name) if exact else next_take_folder(root, name)
        self.fps = fps
        self.meta: dict[str, Any] = {
            "name": name, "fps": fps, "started": _dt.datetime.now(_dt.UTC).isoformat(),
            "mapping": None if mapping_path is None else str(mapping_path),
            "mapping_text": None if mapping_path is None else Path(mapping_path).read_text("utf-8"),
            "devices": dict(devices or {}), **dict(extra or {}), "frames": None, "samples": None,
            "complete": False, "error": None,
        }
        try:
            self._write_meta()
            self._fap = FapWriter(self.folder / FAP_NAME, fps, self.folder.name)
            self._log = SampleLogWriter(self.folder / LOG_NAME)
        except OSError as exc:
            raise TakeError(f"{self.folder}: cannot start the take: {exc.strerror or exc}") from exc
        self.frames = 0
        self._sounds: dict[str, WavWriter] = {}

    def sample(self, sample: Sample) -> None:
        """Log one raw Sample (call for every Sample, in arrival order), and its sound."""
        self._log.write(sample)
        if sample.sound is not None:
            self._sound(sample)

    def samples(self, samples: list[Sample]) -> None:
        """Log a run of raw Samples (as ``sample`` each, queued together)."""
        self._log.write_all(samples)
        for sample in samples:
            if sample.sound is not None:
                self._sound(sample)

    def _sound(self, sample: Sample) -> None:
        """Append a Sample's sound to its device's WAV (the first block opens it, and the
        metadata says where it falls and what the analysis's state was)."""
        sound = sample.sound
        assert sound is not None  # the caller passes Samples with sound
        writer = self._sounds.get(sample.device)
        if writer is None:
            name = SOUND_NAME if not self._sounds else f"take.{sample.device}.wav"
            state = None if sound.state is None else json_state(sound.state)
            self.meta.setdefault("sound", {})[sample.device] = {
                "file": name, "rate": sound.rate, "first_ns": sound.start_ns, "frames": 0, "state": state}
            writer = self._sounds[sample.device] = WavWriter(self.folder / name, sound.rate)
            self._write_meta()
        writer.write(sound.pcm)

    def event(self, event: LogEvent) -> None:
        """Log one event (hold, resume, reset, frame) in its place among the Samples."""
        self._log.event(event)

    def frame(self, fap: np.ndarray, viseme: tuple[float, ...] | None = None,
              expression: tuple[float, ...] | None = None) -> None:
        """Write one frame: 68 low-level FAP values (FAPU; FAP 1/2 columns ignored) and the blends.
        The log's entries queued so far reach its file first: a take cut short anywhere has a log
        holding every entry that decided its frames."""
        self._log.sync()
        write_pose(self._fap, fap, viseme, expression)
        self.frames += 1

    def close(self) -> Path:
        """Finish the take (final counts in its metadata, marked complete); returns its folder."""
        self._fap.close()
        self._log.close()
        self._close_sounds()
        self.meta.update(frames=self.frames, samples=self._log.count, complete=True)
        self._write_meta()
        return self.folder

    def abandon(self, reason: str) -> Path:
        """Stop after a failed write (disk full, folder gone): close what can be closed and say
        in the metadata, if it can still be written, that the take is incomplete and why. What
        reached the disk stays readable to its last complete frame and line."""
        for part in (self._fap, self._log):
            with contextlib.suppress(Exception):  # the log's thread raises whatever failed it
                part.close()
        try:
            self._close_sounds()
        except OSError:
            pass
        self.meta.update(frames=self.frames, samples=self._log.count, complete=False, error=reason)
        try:
            self._write_meta()
        except OSError:
            pass  # take.json still says "complete": false from the start
        return self.folder

    def _close_sounds(self) -> None:
        for device, writer in self._sounds.items():
            writer.close()
            self.meta["sound"][device]["frames"] = writer.frames

    def __enter__(self) -> TakeRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _write_meta(self) -> None:
        partial = self.folder / f".{META_NAME}.partial"
        partial.write_text(json.dumps(self.meta, indent=1) + "\n", "utf-8")
        partial.replace(self.folder / META_NAME)


def write_pose(writer: FapWriter, fap: np.ndarray, viseme: tuple[float, ...] | None = None,
               expression: tuple[float, ...] | None = None) -> None:
    """Write a Pose's values as one .fap frame: FAPs 3..68 always, FAP 1 / 2 when given."""
    mask = np.ones(68, dtype=bool)
    mask[:2] = viseme is not None, expression is not None
    writer.write_frame(np.asarray(fap, dtype=float), mask,
                       viseme=None if viseme is None else (*viseme[:3], 0),
                       expression=None if expression is None else (*expression[:4], 0, 0))


@dataclass(frozen=True)
class TakeSound:
    """One audio device's sound in a take: its WAV, rate, the clock time of its first frame, and
    the analysis's state before it."""

    device: str
    path: Path
    rate: int
    first_ns: int
    state: dict[str, Any] | None = None


@dataclass
class Take:
    """A recorded take, read back."""

    folder: Path
    meta: dict[str, Any]

    @property
    def fap_path(self) -> Path:
        return self.folder / FAP_NAME

    @property
    def log_path(self) -> Path:
        return self.folder / LOG_NAME

    def stream(self) -> FapStream:
        return read_fap(self.present(FAP_NAME))

    def sounds(self) -> list[TakeSound]:
        """The sound each audio device recorded, as the metadata describes it (the files are
        read on demand; one may be missing or damaged)."""
        return [TakeSound(device, self.folder / info["file"], info["rate"], info["first_ns"], info.get("state"))
                for device, info in (self.meta.get("sound") or {}).items()]

    def samples(self) -> Iterator[Sample]:
        return self._log(read_samples)

    def entries(self) -> Iterator[Sample | LogEvent]:
        """The log's Samples and events, in order (what replay feeds a ``TakeClock``)."""
        return self._log(read_take_log)

    def present(self, name: str) -> Path:
        """The path of the take's file ``name``; a TakeError if it is not there."""
        path = self.folder / name
        if not path.is_file():
            raise TakeError(f"{self.folder}: the take has no {name} (deleted or never written)")
        return path

    def _log(self, read: Callable[[Path], Iterator[Any]]) -> Iterator[Any]:
        """``read``'s entries of the log; whatever the log's reader refuses becomes a TakeError."""
        path = self.present(LOG_NAME)
        count = 0
        try:
            for entry in read(path):
                yield entry
                count += 1
        except (ValueError, TypeError, OverflowError, RecursionError) as exc:
            why = "a line nests too deeply" if isinstance(exc, RecursionError) else str(exc)
            raise TakeError(f"{path}: unreadable after {count} entries: {why}") from None


def _of(kind: type) -> Callable[[object], bool]:
    """A check for JSON values of ``kind`` (booleans are not integers here)."""
    if kind is bool:
        return lambda value: isinstance(value, bool)
    return lambda value: isinstance(value, kind) and not isinstance(value, bool)


def _optional(check: Callable[[object], bool]) -> Callable[[object], bool]:
    return lambda value: value is None or check(value)


def _dict_of(check: Callable[[object], bool]) -> Callable[[object], bool]:
    return lambda value: isinstance(value, dict) and all(check(v) for v in value.values())


def _state(value: object) -> bool:
    return (isinstance(value, dict) and _of(int)(value.get("seq"))
            and _dict_of(lambda c: isinstance(c, dict))(value.get("channels")))


def _layer(value: object) -> bool:
    return (isinstance(value, dict) and _of(str)(value.get("over")) and isinstance(value.get("slots"), list)
            and all(_of(int)(s) and 0 <= s < 68 for s in value["slots"])
            and _of(bool)(value.get("viseme")) and _of(bool)(value.get("expression")))


_COUNT = _optional(lambda v: _of(int)(v) and v >= 0)  # type: ignore[operator]  # an int by then


def _sound(value: object) -> bool:
    return (isinstance(value, dict) and _of(str)(value.get("file")) and bool(SOUND_FILE.fullmatch(value["file"]))
            and _of(int)(value.get("rate")) and 1000 <= value["rate"] <= 384000 and _of(int)(value.get("first_ns"))
            and _COUNT(value.get("frames")) and _optional(lambda v: isinstance(v, dict))(value.get("state")))


META_TYPES: dict[str, tuple[Callable[[object], bool], str]] = {
    "name": (_of(str), "a string"),
    "fps": (lambda v: _of(int)(v) and v in FPS_CHOICES, f"one of {FPS_CHOICES}"),
    "started": (_optional(_of(str)), "a time (string) or null"),
    "mapping": (_optional(_of(str)), "a path (string) or null"),
    "mapping_text": (_optional(_of(str)), "the mapping's text (string) or null"),
    "devices": (_dict_of(_of(str)), "an object of device names to URLs (strings)"),
    "wire": (_optional(_dict_of(_optional(lambda v: isinstance(v, dict)))), "an object of objects or null"),
    "t0_ns": (_optional(_of(int)), "an integer (ns) or null"),
    "hold_ns": (_optional(_of(int)), "an integer (ns) or null"),
    "mapping_state": (_optional(_state), 'a mapping state {"seq": int, "channels": {...}} or null'),
    "layer": (_optional(_layer), 'a layer {"over": path, "slots": [0-67 ...], "viseme": bool, '
              '"expression": bool} or null'),
    "sound": (_optional(_dict_of(_sound)), 'an object of device names to {"file": "take.wav", "rate": Hz, '
              '"first_ns": int, "frames": count, "state": {...}} or null'),
    "frames": (_COUNT, "a count (integer >= 0) or null"),
    "samples": (_COUNT, "a count (integer >= 0) or null"),
    "complete": (_of(bool), "true or false"),
    "error": (_optional(_of(str)), "a message (string) or null"),
}


def open_take(folder: str | os.PathLike[str]) -> Take:
    """Read a take folder's metadata (its .fap and log are read on demand), checked against
    ``META_TYPES``: a TakeError names the file and the first key that is wrong."""
    folder = Path(folder)
    meta_path = folder / META_NAME
    if not folder.exists():
        raise TakeError(f"{folder}: no such take folder")
    if not meta_path.is_file():
        raise TakeError(f"{folder}: not a take (no {META_NAME})")
    try:
        if meta_path.stat().st_size > MAX_META_BYTES:
            raise TakeError(f"{meta_path}: expected metadata of at most {MAX_META_BYTES >> 20} MB,"
                            f" found {meta_path.stat().st_size:,} bytes")
        meta = json.loads(meta_path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise TakeError(f"{meta_path}: expected JSON text, found a byte that is not UTF-8 at"
                        f" {exc.start} (a binary file?)") from None
    except json.JSONDecodeError as exc:
        raise TakeError(f"{meta_path}:{exc.lineno}: not valid JSON ({exc.msg})") from None
    except RecursionError:
        raise TakeError(f"{meta_path}: expected take metadata, found JSON nested too deeply") from None
    except OSError as exc:
        raise TakeError(f"{meta_path}: cannot be read: {exc.strerror or exc}") from None
    _check_meta(meta, meta_path)
    return Take(folder, meta)


def _check_meta(meta: object, path: Path) -> None:
    if not isinstance(meta, dict):
        raise TakeError(f"{path}: expected a JSON object of take metadata, found {type(meta).__name__}"
                        f" {json.dumps(meta)[:40]}")
    for key, (check, expected) in META_TYPES.items():
        if key in meta and not check(meta[key]):
            raise TakeError(f"{path}: {key!r}: expected {expected}, found {json.dumps(meta[key])[:60]}")


def take_fap(path: str | os.PathLike[str]) -> Path:
    """The .fap of a take given as its folder (its metadata checked too) or as the .fap itself.

    A folder whose ``take.json`` is missing but whose ``take.fap`` is there gives that .fap, with
    a warning: the take still plays and renders, but it cannot be replayed from its log."""
    path = Path(path)
    if path.is_dir():
        if not (path / META_NAME).exists() and (path / FAP_NAME).is_file():
            warnings.warn(f"{path}: the take has no {META_NAME}; playing its {FAP_NAME} alone",
                          stacklevel=2)
            return path / FAP_NAME
        return open_take(path).present(FAP_NAME)
    if not path.exists():
        raise TakeError(f"{path}: no such take (expected a take folder or a .fap file)")
    return path
