"""A take's raw log played again into a new .fap: through its own mapping, another mapping, or
through the devices' own wires.

``retake(take, out)`` rebuilds the take's mapping from the text it recorded, restores the state
the mapping had at the take's first frame (``take.json``'s ``mapping_state``) and drives a
``TakeClock`` with the log's Samples and events, exactly as the live session did: the .fap
comes out identical, byte for byte. What it proves: the log holds everything the take is made
of, so a take can always be re-mapped or re-rendered.

* ``mapping=other.yaml`` re-maps the take: the new mapping starts from the take's state at its
  first frame (``Mapping.restore``: exactly where its channels are shaped as before) and turns
  the same performance into other FAPs.
* ``through_devices=True`` sends every logged reading through its device's wire -- serial
  lines or frames on a pseudo-terminal, HID reports from the fake HID source, CAN frames on a
  virtual bus, MIDI messages, OSC datagrams, the take's recorded sound through ``wav://``
  (``devices.twin``) -- where the real adapter reads
  it back; the values it decodes are fed with the logged timestamp (a deterministic clock: the
  adapter's own stamp says when the bytes came back, not when the performer moved). A wire that
  does not carry a value exactly stops the replay with the device, channel and both values.

A take killed mid-write has a log that can run ahead of its .fap (the session logs an entry,
then writes the frames it makes due); so an incomplete take is replayed up to the recorded
.fap's last complete frame, the point where both agree. A recorded .fap that is missing or
unreadable does not stop the replay (that is when it is wanted most): ``Retake.unreadable`` says
why it could not be compared.

Muscle-driven frames are written as FAPs measured on the default face, as the live session does
(``Runtime.muscle_faps``); that face's runtime is built only when a frame contracts a muscle.
"""

from __future__ import annotations

import filecmp
import os
from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

from devices.base import Sample
from puppet.errors import PuppetError
from puppet.io.fapfile import FapError, FapWriter, iter_fap
from puppet.io.outputs import writable
from puppet.io.samplelog import LogEvent
from puppet.io.takes import Take, TakeError, open_take, write_pose
from puppet.live.mappingfile import load_mapping, parse_mapping
from puppet.live.takeclock import Layer, TakeClock, default_muscle_faps


@dataclass(frozen=True)
class Retake:
    """What a replay wrote: the .fap, its frame count, and whether it equals the take's own .fap
    (None when re-mapped: a different mapping is not expected to agree, or when the recorded .fap
    is missing or unreadable: ``unreadable`` says why)."""

    path: Path
    frames: int
    identical: bool | None
    unreadable: str | None = None


def retake(take: str | os.PathLike | Take, out: str | os.PathLike, *, mapping: str | os.PathLike | None = None,
           through_devices: bool = False) -> Retake:
    """Replay ``take``'s raw log into the .fap ``out`` (see the module docstring)."""
    take = take if isinstance(take, Take) else open_take(take)
    meta = take.meta
    missing = [key for key in ("fps", "t0_ns", "mapping_state", "mapping_text") if meta.get(key) is None]
    if missing:
        raise TakeError(f"{take.folder}: the take has no {', '.join(missing)} in its metadata, so its log "
                        "cannot be replayed (it was not recorded by a live session)")
    out = writable(out, ".fap")
    if out.resolve() == take.fap_path.resolve():
        raise TakeError(f"{out}: that is the take's own .fap; write the replay elsewhere")
    recorded = parse_mapping(meta["mapping_text"], meta.get("mapping") or "<take mapping>")
    mapper = recorded if mapping is None else load_mapping(mapping)
    name, frames, unreadable = _recorded(take)
    limit = None if meta.get("complete") or unreadable else frames
    with ExitStack() as stack:
        writer = stack.enter_context(FapWriter(out, meta["fps"], name))

        def write(*frame) -> None:
            if limit is None or writer.frames_written < limit:
                write_pose(writer, *frame)

        clock = TakeClock(mapper, write, meta["t0_ns"], meta["fps"], hold_ns=meta.get("hold_ns"),
                          layer=_layer(take), encode_muscles=default_muscle_faps)
        entries = take.entries()
        if through_devices:
            entries = _through_devices(entries, take, stack)
        _play(take, mapper, recorded, clock, entries, limit)
        written = writer.frames_written
    if mapping is not None or unreadable:
        return Retake(out, written, None, unreadable)
    return Retake(out, written, _same(out, take.fap_path, whole=limit is None))


def _same(out: Path, recorded: Path, *, whole: bool) -> bool:
    """Whether ``out`` equals the recorded .fap (``whole``), or, for a take cut off by a kill,
    equals it up to the cut (the bytes after it are the frame the kill interrupted; the header's
    count may be one short, if the kill came between a frame and its count)."""
    if whole:
        return filecmp.cmp(out, recorded, shallow=False)
    with open(out, "rb") as mine, open(recorded, "rb") as theirs:
        if mine.readline().split()[:-1] != theirs.readline().split()[:-1]:
            return False
        while block := mine.read(1 << 20):
            if theirs.read(len(block)) != block:
                return False
    return True


def _recorded(take: Take) -> tuple[str, int, str | None]:
    """The recorded .fap's name and complete frames, or why it cannot be read."""
    fallback = f"{take.meta.get('name', 'take')}_{take.folder.name[-3:]}"
    try:
        with iter_fap(take.present("take.fap")) as reader:
            return reader.header.name, sum(1 for _ in reader), None
    except (FapError, TakeError) as exc:
        return fallback, 0, f"the recorded take.fap is unreadable: {exc}"
    except OSError as exc:
        return fallback, 0, f"the recorded take.fap is unreadable: {exc.strerror or exc}"


def _play(take: Take, mapper, recorded, clock: TakeClock, entries: Iterator[Sample | LogEvent],
          limit: int | None) -> None:
    """Restore the mapping's state at frame 0 and feed the log to the clock (up to ``limit``
    frames); state or entries the mapping cannot take are a TakeError naming the entry."""
    done = 0
    try:
        mapper.restore(take.meta["mapping_state"], recorded)
        for done, entry in enumerate(entries, 1):
            clock.apply(entry)
            if limit is not None and clock.frames >= limit:
                break
    except PuppetError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError) as exc:
        where = "take.json's mapping_state" if done == 0 else f"log entry {done}"
        raise TakeError(f"{take.folder}: the replay cannot go on at {where}: {type(exc).__name__}: {exc}"
                        " (does the take's metadata fit its mapping and log?)") from None


def _layer(take: Take) -> Layer | None:
    """The take's base layer, found where it was or, moved with its takes, beside this take."""
    spec = take.meta.get("layer")
    if spec is None:
        return None
    over = Path(spec["over"])
    if not over.exists():
        beside = take.folder.parent / over.parent.name / over.name
        if not beside.exists():
            raise TakeError(f"{take.folder}: this take was layered over {over}, which is gone")
        spec = {**spec, "over": str(beside)}
    return Layer.from_spec(spec)


def _through_devices(entries: Iterator[Sample | LogEvent], take: Take,
                     stack: ExitStack) -> Iterator[Sample | LogEvent]:
    """The entries, each Sample's values replaced by what its device's real adapter read back."""
    from devices import open_twin

    urls, wire = take.meta.get("devices") or {}, take.meta.get("wire") or {}
    sounds = {sound.device: {"sound_file": str(sound.path), "sound_state": sound.state} for sound in take.sounds()}
    twins = {}
    for entry in entries:
        if isinstance(entry, Sample):
            twin = twins.get(entry.device)
            if twin is None:
                if entry.device not in urls:
                    raise TakeError(f"{take.folder}: the log has samples of device {entry.device!r}, "
                                    "which the take's metadata does not list")
                info = {**(wire.get(entry.device) or {}), **sounds.get(entry.device, {})}
                twin = twins[entry.device] = open_twin(urls[entry.device], entry.device, info)
                stack.callback(twin.close)
            entry = Sample(entry.t_ns, entry.device, twin.exchange(entry.values).values)
        yield entry
