"""A take's frame clock: the Pose written at ``t0 + k / fps``, between the entries of its log.

The live session and the replay drive one ``TakeClock`` with the same entries in the same
order -- the Samples and the log events of ``puppet.io.samplelog`` -- so replaying a take's log
writes exactly the frames the live session wrote:

* a Sample: every tick before its timestamp is written (with the pose the entries before it
  made), then the Sample is fed to the mapping;
* ``frame`` at t: every tick at or before t is written (the session logs one whenever a frame of
  the live loop wrote ticks after its last Sample);
* ``hold`` at t: a device is away; ticks are evaluated at ``min(tick, t)``, so the take holds
  the pose of the moment it went (other devices' new Samples still come through, and the
  triggers and idle life (``puppet.live.idlelife``) play on at the tick);
* ``resume``: every device is back; ticks run at their own time again;
* ``reset``: ticks before t are written, then every channel goes back to rest (neutral);
* ``recentre``: ticks before t are written, then the bipolar channels take the logged centres;
* ``trigger``: ticks before t are written, then the named trigger is pressed, released or fired
  (``Mapping.trigger``; a mapping without that trigger, re-mapping a take, lets it pass);
* ``newest`` with ``count`` n: the next n Samples are a flood the live loop took as a run
  (``apply_newest``): between two ticks, each channel takes its newest reading
  (``Mapping.feed_newest``), so the take's filters step once a frame, as the face's did.

Layered passes: with a ``Layer``, each frame is the base take's frame with the armed FAPs
replaced by the pose, as animators layer one pass over another.

Muscles: a .fap holds FAPs only, so a frame whose pose contracts a muscle is written as the pose's
FAPs plus ``encode_muscles(pose.muscles)``, the FAPs the muscles' motion measures on the face
(``Runtime.muscle_faps``); the live session and the replay pass the same encoder.
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np

from devices.base import Sample
from puppet.fap.held import HeldFaps
from puppet.fap.pose import Pose
from puppet.fap.table import faps
from puppet.io.fapfile import iter_fap
from puppet.io.samplelog import LogEvent
from puppet.io.takes import TakeError
from puppet.live.channels import Mapping

WriteFrame = Callable[[np.ndarray, "tuple | np.ndarray | None", "tuple | np.ndarray | None"], None]
"""Writes one frame: 68 FAP values (FAPU; FAP 1/2 slots unused), viseme and expression fields."""
EncodeMuscles = Callable[[dict], np.ndarray]
"""68 FAP values (FAPU) that muscle contractions {name: c} amount to."""


def default_muscle_faps(muscles: dict[str, float]) -> np.ndarray:
    """``encode_muscles`` on the default face (its runtime made on first use): for takes made
    without a live runtime at hand (an import, a replay, a benchmark)."""
    return _default_runtime().muscle_faps(muscles)


@functools.cache
def _default_runtime():
    from puppet.face.load import load_face
    from puppet.runtime.runtime import Runtime

    return Runtime(load_face())


def _time(sample: Sample) -> int:
    return sample.t_ns


class Layer:
    """A base take under a layered pass: frame k of the base, with the armed FAPs (and, when
    armed, the viseme or expression) taken from the live pose instead. The base is streamed
    (frames asked for in increasing order), holding its last frame once it ends."""

    def __init__(self, base_fap: str | os.PathLike, slots: Iterable[int], *,
                 viseme: bool = False, expression: bool = False) -> None:
        self.base_fap = Path(base_fap)
        self.slots = np.array(sorted(set(slots)), dtype=int)
        self.viseme, self.expression = viseme, expression
        with iter_fap(self.base_fap) as reader:
            self.total = reader.header.declared_frames  # the base's frame count, as its header says
            self.fps = reader.header.fps
        self._frames: Iterator = iter(iter_fap(self.base_fap))
        self._held = HeldFaps.neutral()
        self._index = -1

    def at(self, k: int) -> HeldFaps:
        """The base take's held FAPs at frame ``k`` (never before the last one asked for)."""
        while self._index < k:
            frame = next(self._frames, None)
            if frame is None:
                break
            self._held.update(frame)
            self._index += 1
        return self._held

    def merge(self, k: int, pose: Pose) -> tuple[np.ndarray, np.ndarray | tuple | None, np.ndarray | tuple | None]:
        """(fap, viseme, expression) of layered frame ``k``."""
        base = self.at(k)
        fap = base.values.copy()
        fap[:2] = 0.0
        fap[self.slots] = pose.fap[self.slots]
        viseme = pose.viseme if self.viseme else base.viseme
        expression = pose.expression if self.expression else base.expression
        return fap, viseme, expression

    def describe(self, k: int) -> str:
        """The pass as the performer needs it: the base take, where it is (frame and time, of its
        length), and what is armed: ``over take_001, frame 16 of 98 (0:00.60 of 0:03.92); armed: open_jaw``."""
        where = f"frame {k + 1}" + (f" of {self.total}" if self.total else "")
        when = _clock(k / self.fps) + (f" of {_clock(self.total / self.fps)}" if self.total else "")
        return f"over {self._said[0]}, {where} ({when}); armed: {self._said[1]}"

    @functools.cached_property
    def _said(self) -> tuple[str, str]:
        """The base take's name and what is armed, as ``describe`` says them (made once, not per frame)."""
        names = {f.number - 1: f.name for f in faps()}
        armed = [names[slot] for slot in self.slots] + ["viseme"] * self.viseme + ["expression"] * self.expression
        shown = ", ".join(armed[:4]) + (f" and {len(armed) - 4} more" if len(armed) > 4 else "")
        base = self.base_fap.parent.name if self.base_fap.name == "take.fap" else self.base_fap.name
        return base, shown

    def spec(self) -> dict:
        """What a take's metadata keeps to rebuild this layer."""
        return {"over": str(self.base_fap.resolve()), "slots": self.slots.tolist(),
                "viseme": self.viseme, "expression": self.expression}

    @classmethod
    def from_spec(cls, spec: dict) -> Layer:
        return cls(spec["over"], spec["slots"], viseme=spec["viseme"], expression=spec["expression"])

    def restarted(self) -> Layer:
        """The same layer, its base streamed from the first frame again (for the next pass)."""
        return Layer(self.base_fap, self.slots, viseme=self.viseme, expression=self.expression)

    @classmethod
    def armed(cls, base_fap: str | os.PathLike, mapping: Mapping, arm: Iterable[str]) -> Layer:
        """A layer whose armed targets are named by ``arm``: channels (``box.ch0``: whatever
        that channel drives), FAP numbers or names (``3``, ``open_jaw``), ``viseme``,
        ``expression``."""
        names = {f.name: f.number for f in faps()}
        slots: set[int] = set()
        kinds: set[str] = set()
        for item in arm:
            if "." in item:
                try:
                    channel_slots, channel_kinds = mapping.drives(item)
                except KeyError as error:
                    raise TakeError(f"arm {item!r}: {error.args[0]}") from None
                slots |= channel_slots
                kinds |= channel_kinds
            elif item in ("viseme", "expression"):
                kinds.add(item)
            elif item.isdigit() and 3 <= int(item) <= 68:
                slots.add(int(item) - 1)
            elif item in names:
                slots.add(names[item] - 1)
            else:
                raise TakeError(f"arm {item!r}: expected a channel (device.channel), a FAP number 3..68 "
                                 "or name (e.g. open_jaw), 'viseme' or 'expression'")
        if not slots and not kinds & {"viseme", "expression"}:
            raise TakeError(f"arm {list(arm)}: these drive no FAP, viseme or expression, so the pass "
                             "would only copy the base take")
        return cls(base_fap, slots, viseme="viseme" in kinds, expression="expression" in kinds)


class TakeClock:
    """Writes a take's frames at its fps from a stream of log entries (see the module docstring)."""

    def __init__(self, mapping: Mapping, write: WriteFrame, t0_ns: int, fps: int, *,
                 hold_ns: int | None = None, layer: Layer | None = None,
                 encode_muscles: EncodeMuscles | None = None) -> None:
        self.mapping, self.write = mapping, write
        self.t0_ns, self.fps = int(t0_ns), int(fps)
        self.hold_ns = hold_ns
        self.layer = layer
        self.encode_muscles = encode_muscles
        self.frames = 0
        self._run: list[Sample] = []   # a ``newest`` run being gathered, and how many it takes
        self._run_left = 0

    def tick_ns(self, k: int) -> int:
        return self.t0_ns + (k * 1_000_000_000) // self.fps

    def due(self, t_ns: int) -> bool:
        """Whether a ``frame`` entry at ``t_ns`` would write a frame."""
        return self.tick_ns(self.frames) <= t_ns

    def apply(self, entry: Sample | LogEvent) -> None:
        if self._run_left:
            if not isinstance(entry, Sample):
                raise ValueError(f"a {entry.kind!r} event inside a run of newest readings "
                                 f"({self._run_left} Samples still to come)")
            self._run.append(entry)
            self._run_left -= 1
            if not self._run_left:
                run, self._run = self._run, []
                self.apply_newest(run)
            return
        if isinstance(entry, Sample):
            self._until(entry.t_ns)
            self.mapping.feed(entry)
        elif entry.kind == "frame":
            self._until(entry.t_ns + 1)
        elif entry.kind == "hold":
            self.hold_ns = entry.t_ns
        elif entry.kind == "resume":
            self.hold_ns = None
        elif entry.kind == "reset":
            self._until(entry.t_ns)
            self.mapping.reset()
        elif entry.kind == "recentre":
            self._until(entry.t_ns)
            self.mapping.recentre(entry.data["centres"])
        elif entry.kind == "trigger":
            self._until(entry.t_ns)
            if entry.data["name"] in self.mapping.trigger_names:
                self.mapping.trigger(entry.data["name"], entry.data["action"], entry.t_ns)
        elif entry.kind == "newest":
            self._run_left = int(entry.data["count"])
        else:
            raise ValueError(f"unknown log event {entry.kind!r}")

    def apply_newest(self, samples: list[Sample]) -> None:
        """A run of Samples (in time order) taken as the live loop takes a flood: the readings
        between two ticks are fed as one (``Mapping.feed_newest``), each tick written before
        the readings after it, as ``apply`` writes them."""
        i = 0
        while i < len(samples):
            self._until(samples[i].t_ns)
            tick = self.tick_ns(self.frames)  # the next tick, at or after this reading
            j = bisect.bisect_right(samples, tick, lo=i + 1, key=_time)
            self.mapping.feed_newest(samples[i:j])
            i = j

    def _until(self, before_ns: int) -> None:
        """Write every tick strictly before ``before_ns`` not yet written."""
        while (tick := self.tick_ns(self.frames)) < before_ns:
            t = tick if self.hold_ns is None else min(tick, self.hold_ns)
            pose = self.mapping.pose(t, tick)
            if self.encode_muscles is not None and any(pose.muscles.values()):
                pose = dataclasses.replace(pose, fap=pose.fap + self.encode_muscles(pose.muscles))
            if self.layer is None:
                self.write(pose.fap, pose.viseme, pose.expression)
            else:
                self.write(*self.layer.merge(self.frames, pose))
            self.frames += 1


def _clock(seconds: float) -> str:
    """``m:ss.ss``, a time into the base take."""
    return f"{int(seconds) // 60}:{seconds % 60:05.2f}"
