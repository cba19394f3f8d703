"""The channel engine: a checked mapping compiled into what runs on every Sample.

A channel is shaped in this order: calibrate (clamped to the range) -> invert -> button (toggle /
momentary: the channel becomes 0 or 1) or dead zone -> curve -> smoothing -> rate limit.
Curves act on the magnitude (a bipolar channel keeps its sign): ``linear``; ``expo`` with
``factor`` k in 0..1, ``(1 - k) x + k x^3``; ``gamma``, ``x ** gamma``; ``points``, a
piecewise-linear curve through ``[[0, y0], ..., [1, yn]]`` (x strictly rising, y never falling).
Smoothing is ``{type: one_euro, min_cutoff, beta, d_cutoff}`` or ``{type: exponential, tau}``
(seconds), both driven by the samples' timestamps (``puppet.live.filters``).

A target takes one source or a list (``combine: sum`` (default), ``max`` -- the largest
magnitude, sign kept -- or ``last``, the source fed most recently), multiplies by ``gain``
(default 1), maps the source domain (0..1 or -1..1; a target's sources must agree) linearly onto
``range`` and clamps to it (so a bipolar source's centre lands midway: give it a symmetric range,
``[-200, 200]``, for a face at rest when the control is). ``range`` is required for ``fap``,
``head``, ``eyes``, ``eye_l`` and ``eye_r``: degrees for the rotations, written as FAPs 48-50 /
23-26 in AU with each FAP's own positive direction (pitch down, yaw toward the face's left, roll
toward its right). Muscles (the default face's, ``puppet.face.muscles.MUSCLE_NAMES``; an unknown
name names the closest) default to [0, 1], a contraction; visemes (blend) and expressions
(intensity) to [0, 63]. Targets that write the same FAP or muscle add up. One source may feed any number of targets.

Visemes and expressions become the Pose's FAP 1 / FAP 2 fields: the strongest viseme is
``(select, 0, blend)`` (blended against viseme 0, none), the two strongest expressions are
``(select1, intensity1, select2, intensity2)``; any weaker ones are expanded into low-level FAPs
and added to ``Pose.fap``, so the face changes continuously when the order of strengths changes.

Triggers (``puppet.live.triggers``) put whole poses on presses of a channel or on calls by name
(``trigger``): their expression and viseme strengths join the targets' in the FAP 1 / 2 ranking,
their FAPs and muscles add; the envelopes run on the Samples' timestamps and the pose time.

``feed(sample)`` shapes the sample's channels at once (plain Python floats, no per-sample dict or
YAML walking beyond the sample's own values); ``pose()`` combines the targets into a ``Pose``.

Idle life (``puppet.live.idlelife``: blinks, eye saccades and drift, breath) is added to the FAPs
of a timed ``pose``, part by part, while no target that writes the part's FAPs is away from its
rest; its seed and origin are part of ``snapshot()``, so a take's replay makes the same motion.

The channels and targets come checked from the mapping file (``puppet.live.mappingfile``), as
``ChannelSpec`` and ``TargetSpec``; nothing here reads YAML.
"""

from __future__ import annotations

import bisect
import math
import time
from dataclasses import dataclass

import numpy as np

from devices.base import Sample
from puppet.fap.highlevel import high_level_faps
from puppet.fap.pose import Pose
from puppet.fap.table import N_FAPS, faps
from puppet.fap.units import AU
from puppet.live.filters import Exponential, OneEuro, RateLimit
from puppet.live.idlelife import ALL_ON, PART_FAPS, IdleLife, IdleSpec, random_seed
from puppet.live.triggers import Triggers, TriggerSpec, TriggerState

COMBINE_MODES = ("sum", "max", "last")
EXPRESSIONS = {"joy": 1, "sadness": 2, "anger": 3, "fear": 4, "disgust": 5, "surprise": 6}
HEAD_AXES = {"pitch": (48,), "yaw": (49,), "roll": (50,)}
EYE_AXES = {"eyes": {"yaw": (23, 24), "pitch": (25, 26)},
            "eye_l": {"yaw": (23,), "pitch": (25,)},
            "eye_r": {"yaw": (24,), "pitch": (26,)}}
DEG_TO_AU = math.pi / 180.0 / AU


@dataclass
class ChannelSpec:
    """One channel as its mapping shapes it (checked): device, calibration, shaping steps."""

    name: str
    device: str
    channel: str
    bipolar: bool
    low: float
    centre: float
    high: float
    invert: bool = False
    dead_zone: float = 0.0
    curve: tuple | None = None          # ("expo", k) | ("gamma", g) | ("points", xs, ys)
    smoothing: tuple | None = None      # ("one_euro", min_cutoff, beta, d_cutoff) | ("exponential", tau)
    rate_limit: float | None = None
    button: tuple | None = None         # (mode, threshold, release)


@dataclass
class TargetSpec:
    """One target as its mapping sends to it (checked): kind, key, sources, combine, range, gain."""

    kind: str
    key: object                          # FAP number, muscle name, viseme / expression number, axis
    sources: list[str]
    combine: str = "sum"
    range: tuple[float, float] | None = None
    gain: float = 1.0


@dataclass(frozen=True)
class ChannelState:
    """What a monitor shows for one channel: the last raw value (None before any), the shaped
    value, the targets it drives, and where the raw value sits in the channel's calibrated range
    (0 at ``min``, 1 at ``max``; None before any)."""

    name: str
    raw: float | None
    value: float
    targets: tuple[str, ...]
    raw_fraction: float | None = None


def _curve_function(curve: tuple | None):
    """The curve as a function of the magnitude 0..1 (None for linear)."""
    if curve is None:
        return None
    if curve[0] == "expo":
        k = curve[1]
        return lambda m: m * ((1.0 - k) + k * m * m)
    if curve[0] == "gamma":
        g = curve[1]
        return lambda m: m ** g
    xs, ys = curve[1], curve[2]
    last = len(xs) - 2

    def points(m: float) -> float:
        i = bisect.bisect_right(xs, m) - 1
        i = 0 if i < 0 else last if i > last else i
        t = (m - xs[i]) / (xs[i + 1] - xs[i])   # each step is monotonic in m, however close the xs
        y = ys[i] + t * (ys[i + 1] - ys[i])
        return ys[i] if y < ys[i] else ys[i + 1] if y > ys[i + 1] else y

    return points


class _Channel:
    """One source channel, shaped in place on every sample (plain floats, no allocation)."""

    __slots__ = ("name", "bipolar", "low", "centre", "k", "k_low", "k_high", "invert", "dead",
                 "curve", "button", "threshold", "release", "pressed", "latched", "smoother",
                 "limiter", "timed", "raw", "pre", "value", "out", "t_ns", "seq", "targets")

    def __init__(self, spec: ChannelSpec) -> None:
        self.name = spec.name
        self.bipolar = spec.bipolar
        self.low, self.centre = spec.low, spec.centre
        self.k = 1.0 / (spec.high - spec.low)
        self.k_low = 1.0 / (spec.centre - spec.low)
        self.k_high = 1.0 / (spec.high - spec.centre)
        self.invert = spec.invert
        self.dead = spec.dead_zone
        self.curve = _curve_function(spec.curve)
        self.button = spec.button[0] if spec.button else None
        self.threshold, self.release = (spec.button[1], spec.button[2]) if spec.button else (0.0, 0.0)
        if spec.smoothing is None:
            self.smoother = None
        elif spec.smoothing[0] == "one_euro":
            self.smoother = OneEuro(*spec.smoothing[1:])
        else:
            self.smoother = Exponential(spec.smoothing[1])
        self.limiter = RateLimit(spec.rate_limit) if spec.rate_limit else None
        self.timed = self.smoother is not None or self.limiter is not None
        self.targets: list[str] = []
        self.reset()

    def reset(self) -> None:
        self.raw = None
        self.pre = self.value = self.out = 0.0
        self.t_ns = None
        self.seq = -1
        self.pressed = self.latched = False
        for f in (self.smoother, self.limiter):
            if f is not None:
                f.reset()

    def update(self, raw: float, t_ns: int, seq: int) -> None:
        self.raw = raw
        if self.bipolar:
            d = raw - self.centre
            x = d * self.k_high if d >= 0.0 else d * self.k_low
            x = 1.0 if x > 1.0 else -1.0 if x < -1.0 else x
            if self.invert:
                x = -x
        else:
            x = (raw - self.low) * self.k
            x = 1.0 if x > 1.0 else 0.0 if x < 0.0 else x
            if self.invert:
                x = 1.0 - x
        if self.button is not None:
            if self.pressed:
                if x < self.release:
                    self.pressed = False
            elif x >= self.threshold:
                self.pressed = True
                self.latched = not self.latched
            x = 1.0 if (self.latched if self.button == "toggle" else self.pressed) else 0.0
        else:
            m = -x if x < 0.0 else x
            if self.dead:
                m = 0.0 if m <= self.dead else (m - self.dead) / (1.0 - self.dead)
            if self.curve is not None:
                m = self.curve(m)
            x = -m if x < 0.0 else m
        self.pre = x
        if self.smoother is not None:
            x = self.smoother.step(x, t_ns)
        if self.limiter is not None:
            x = self.limiter.step(x, t_ns)
        self.value = self.out = x
        self.t_ns = t_ns
        self.seq = seq

    _STATE = ("raw", "pre", "value", "out", "t_ns", "seq", "pressed", "latched", "centre", "k_low", "k_high")

    def recentre(self, centre: float) -> bool:
        """Make ``centre`` the rest point of a bipolar channel (a stick that drifted); False when
        it is not strictly inside the channel's range (nothing changes)."""
        high = self.low + 1.0 / self.k
        if not (self.bipolar and self.low < centre < high):
            return False
        self.centre = centre
        self.k_low, self.k_high = 1.0 / (centre - self.low), 1.0 / (high - centre)
        return True

    def snapshot(self) -> dict:
        """Everything ``update`` has built up, as JSON-able data (see ``Mapping.snapshot``)."""
        data = {key: getattr(self, key) for key in self._STATE}
        for key in ("smoother", "limiter"):
            f = getattr(self, key)
            data[key] = None if f is None else f.snapshot()
        return data

    def restore(self, data: dict) -> None:
        for key in self._STATE:
            setattr(self, key, data[key])
        for key in ("smoother", "limiter"):
            f = getattr(self, key)
            if f is not None and data.get(key) is not None:
                f.restore(data[key])

    def preview(self, t_ns: int) -> float:
        """The value a sample repeating the last input at ``t_ns`` would give (nothing is kept)."""
        x = self.pre
        if self.smoother is not None:
            x = self.smoother.peek(x, t_ns)
        if self.limiter is not None:
            x = self.limiter.peek(x, t_ns)
        return x


_SUM, _MAX, _LAST = 0, 1, 2


class _Guard:
    """Targets whose value came out NaN (a corrupt restored state, say): each holds its last good
    value; ``count`` counts such evaluations and ``first`` says what happened the first time."""

    __slots__ = ("count", "first")

    def __init__(self) -> None:
        self.count, self.first = 0, None

    def held(self, target: _Target) -> float:
        self.count += 1
        if self.first is None:
            self.first = (f"{target.label} came out as NaN; its last good value ({target.last:g}) is held "
                          f"(sources: {', '.join(s.name for s in target.sources)})")
        return target.last


class _Target:
    """One target compiled: its sources, the affine map from their domain onto the range, a clamp."""

    __slots__ = ("kind", "key", "slots", "sources", "mode", "gain", "x0", "scale", "low", "cmin", "cmax",
                 "label", "last", "guard", "rest", "still")

    def __init__(self, spec: TargetSpec, sources: list[_Channel], bipolar: bool, guard: _Guard) -> None:
        self.kind, self.key = spec.kind, spec.key
        self.guard = guard
        self.sources = tuple(sources)
        self.mode = (_SUM, _MAX, _LAST)[COMBINE_MODES.index(spec.combine)]
        self.gain = spec.gain
        low, high = spec.range
        if spec.kind in ("head", "eyes", "eye_l", "eye_r"):
            low, high = low * DEG_TO_AU, high * DEG_TO_AU
        if spec.kind == "fap":
            self.slots = (spec.key - 1,)
        elif spec.kind == "head":
            self.slots = tuple(n - 1 for n in HEAD_AXES[spec.key])
        elif spec.kind in EYE_AXES:
            self.slots = tuple(n - 1 for n in EYE_AXES[spec.kind][spec.key])
        else:
            self.slots = ()
        self.x0 = -1.0 if bipolar else 0.0
        self.scale = (high - low) / (1.0 - self.x0)
        self.low = low
        self.cmin, self.cmax = min(low, high), max(low, high)
        if spec.kind == "muscle":
            self.cmin, self.cmax = max(self.cmin, 0.0), min(self.cmax, 1.0)
        elif spec.kind in ("viseme", "expression"):
            self.cmin, self.cmax = max(self.cmin, 0.0), min(self.cmax, 63.0)
        name = ""
        if spec.kind == "fap":
            name = faps()[spec.key - 1].name
        elif spec.kind == "expression":
            name = next(k for k, v in EXPRESSIONS.items() if v == spec.key)
        self.label = f"{spec.kind} {spec.key}" + (f" {name}" if name else "")
        rest = low - self.x0 * self.scale  # every source at 0: the value before any sample
        self.last = self.rest = self.cmin if rest < self.cmin else self.cmax if rest > self.cmax else rest
        self.still = 1e-3 * (self.cmax - self.cmin)  # how far from rest still counts as at rest

    def away(self) -> bool:
        """Whether the last value left rest (by more than 0.1% of the range: a filter's tail does not)."""
        d = self.last - self.rest
        return (d if d >= 0.0 else -d) > self.still

    def evaluate(self) -> float:
        sources = self.sources
        if len(sources) == 1:
            x = sources[0].out
        elif self.mode == _SUM:
            x = 0.0
            for s in sources:
                x += s.out
        elif self.mode == _MAX:
            x = 0.0
            for s in sources:
                v = s.out
                if (v if v >= 0.0 else -v) > (x if x >= 0.0 else -x):
                    x = v
        else:
            best = sources[0]
            for s in sources:
                if s.seq > best.seq:
                    best = s
            x = best.out
        v = self.low + (self.gain * x - self.x0) * self.scale
        v = self.cmin if v < self.cmin else self.cmax if v > self.cmax else v
        if v != v:  # NaN (the clamp lets it through): hold the last good value, and say so
            return self.guard.held(self)
        self.last = v
        return v


class Mapping:
    """A checked, compiled mapping: ``feed`` Samples in, take ``pose()`` out.

    ``devices`` is {name: URL} (per-device options folded into the URL's query) for the session
    to open; Samples whose ``device`` is one of these names are shaped, others are ignored.
    ``triggers`` (``puppet.live.triggers``) are pressed by their source channels as they are
    fed, or by name (``trigger``), and add to every pose."""

    def __init__(self, file: str, devices: dict[str, str], channels: dict[str, ChannelSpec],
                 targets: list[TargetSpec], description: str = "",
                 triggers: list[TriggerSpec] | tuple[TriggerSpec, ...] = (), idle: IdleSpec | None = ALL_ON) -> None:
        self.file = file
        self.description = description
        self.devices = dict(devices)
        self.bad_values = 0
        self._seq = 0
        self._specs = dict(channels)
        self._channels = {name: _Channel(spec) for name, spec in channels.items()}
        self._by_device: dict[str, dict[str, _Channel]] = {}
        for spec in channels.values():
            self._by_device.setdefault(spec.device, {})[spec.channel] = self._channels[spec.name]
        self._timed = tuple(c for c in self._channels.values() if c.timed)
        self._edges: dict[str, frozenset[str]] = {}  # per device: channels whose every reading counts
        self._guard = _Guard()
        compiled = []
        for spec in targets:
            sources = [self._channels[s] for s in spec.sources]
            target = _Target(spec, sources, sources[0].bipolar, self._guard)
            compiled.append(target)
            for s in sources:
                if target.label not in s.targets:
                    s.targets.append(target.label)
        self._faps = tuple(t for t in compiled if t.slots)
        self._muscles = tuple(t for t in compiled if t.kind == "muscle")
        self._visemes = tuple(t for t in compiled if t.kind == "viseme")
        self._expressions = tuple(t for t in compiled if t.kind == "expression")
        self.triggers = Triggers(triggers, file)
        self._watched = self.triggers.by_source
        for spec in triggers:
            if spec.source is not None:
                self._channels[spec.source].targets.append(f"trigger {spec.name}")
        for device, by_name in self._by_device.items():
            edges = frozenset(name for name, c in by_name.items() if c.button is not None or c.name in self._watched)
            if edges:
                self._edges[device] = edges
        self.muscle_names = tuple(dict.fromkeys([*(t.key for t in self._muscles), *self.triggers.muscle_names]))
        self._ranks_visemes = bool(self._visemes or self.triggers.visemes)
        self._ranks_expressions = bool(self._expressions or self.triggers.expressions)
        self._shapes = high_level_faps() if self._ranks_visemes or self._ranks_expressions else None
        self.idle_spec = idle
        self.idle = None if idle is None or not idle.parts else IdleLife(
            random_seed() if idle.seed is None else idle.seed, time.monotonic_ns(), idle.parts)
        self._yield_to = {part: self._drivers(part) for part in PART_FAPS}
        self._yielded: tuple[str, ...] = ()

    # -- the hot path --------------------------------------------------------------------------

    def feed(self, sample) -> None:
        """Shape the channels of one Sample (``t_ns``, ``device``, ``values``); filters use ``t_ns``."""
        channels = self._by_device.get(sample.device)
        if channels is None:
            return
        t_ns = sample.t_ns
        watched = self._watched
        for name, raw in sample.values.items():
            channel = channels.get(name)
            if channel is None:
                continue
            try:
                raw = float(raw)
            except (TypeError, ValueError, OverflowError):
                self.bad_values += 1
                continue
            if raw != raw:  # NaN (the cheapest test for it): garbage from the device, skipped
                self.bad_values += 1
                continue
            self._seq += 1
            channel.update(raw, t_ns, self._seq)
            if watched and channel.name in watched:
                self.triggers.input(channel.name, channel.pre, t_ns)

    def feed_newest(self, samples: list[Sample]) -> None:
        """Shape a run of Samples (in time order) as one: each channel takes its newest reading,
        at that reading's device's newest time, so the filters step once for the run -- what a
        loop that cannot map every reading of a flood does, once a frame. Buttons and the
        channels triggers watch still see every reading (a press and release inside the run
        still toggles, still fires)."""
        newest: dict[str, tuple[int, dict]] = {}
        edges = self._edges
        for sample in samples:
            device = sample.device
            if device in edges and not edges[device].isdisjoint(sample.values):
                self.feed(Sample(sample.t_ns, device, {k: v for k, v in sample.values.items() if k in edges[device]}))
            entry = newest.get(device)
            if entry is None:
                newest[device] = (sample.t_ns, dict(sample.values))
            else:
                entry[1].update(sample.values)
                newest[device] = (sample.t_ns, entry[1])
        for device, (t_ns, values) in sorted(newest.items(), key=lambda item: item[1][0]):
            if device in edges:
                values = {k: v for k, v in values.items() if k not in edges[device]}
            self.feed(Sample(t_ns, device, values))

    def pose(self, t_ns: int | None = None, trigger_ns: int | None = None) -> Pose:
        """The Pose for the channels as last fed; with ``t_ns``, smoothing and rate limits are
        carried on to that time with each input held (without changing the state), so the face
        settles between the samples of devices that only report changes. The triggers and idle
        life play at ``trigger_ns`` (default ``t_ns``): a session holding the pose while a device
        is away still plays them on its own clock.

        Idle life (``self.idle``; none without a time) is added part by part, only where no
        target or trigger that writes the part's FAPs is away from rest at that time
        (``idle_yields``): it yields at once, with no fade, and comes back the frame they rest."""
        if t_ns is None:
            for c in self._timed:
                c.out = c.value
        else:
            for c in self._timed:
                c.out = c.preview(t_ns) if c.t_ns is not None and t_ns > c.t_ns else c.value
        fap = np.zeros(N_FAPS)
        for t in self._faps:
            v = t.evaluate()
            for i in t.slots:
                fap[i] += v
        muscles = dict.fromkeys(self.muscle_names, 0.0)
        for t in self._muscles:
            muscles[t.key] += t.evaluate()
        visemes: dict[int, float] = {}
        expressions: dict[int, float] = {}
        if self.triggers:
            self.triggers.add(t_ns if trigger_ns is None else trigger_ns, fap, muscles, expressions, visemes)
        for name, v in muscles.items():
            muscles[name] = 0.0 if v < 0.0 else 1.0 if v > 1.0 else v
        viseme = self._viseme(fap, visemes) if self._ranks_visemes else None
        expression = self._expression(fap, expressions) if self._ranks_expressions else None
        at = t_ns if trigger_ns is None else trigger_ns
        if self.idle is not None and at is not None:
            self._yielded = self._yields(at)
            self.idle.add_to(fap, at, self._yielded)
        return Pose(fap, viseme, expression, muscles, t_ns)

    def _drivers(self, part: str) -> tuple[tuple[_Target, ...], tuple]:
        """What writes a part's FAPs: the targets (FAP, head and eye targets on them, visemes and
        expressions whose shapes move them, and for the blink the muscles that shut the eye)
        and the triggers (FAPs, expressions, visemes or clips that move them, those muscles)."""
        slots = sorted({n - 1 for n in PART_FAPS[part]})
        shapes = self._shapes or {}

        def moves(kind: str, key) -> bool:
            shape = shapes.get(kind, {}).get(key)
            return shape is not None and bool(np.any(shape[slots]))

        eyelids = part == "blink"
        found = [t for t in self._faps if set(slots) & set(t.slots)]
        found += [t for t in self._visemes if moves("visemes", t.key)]
        found += [t for t in self._expressions if moves("expressions", t.key)]
        found += [t for t in self._muscles if eyelids and t.key.startswith("orbicularis_oculi")]
        triggers = [tr for tr in self.triggers.all.values()
                    if (tr.fap is not None and np.any(tr.fap[slots]))
                    or (tr.spec.expression and moves("expressions", tr.spec.expression))
                    or (tr.spec.viseme and moves("visemes", tr.spec.viseme))
                    or (tr.spec.clip is not None and np.any(tr.spec.clip.frames[:, slots]))
                    or (eyelids and any(m.startswith("orbicularis_oculi") for m, _ in tr.spec.muscles))]
        return tuple(found), tuple(triggers)

    def _yields(self, t_ns: int) -> tuple[str, ...]:
        """The idle parts a target away from rest, or a trigger playing at ``t_ns``, drives."""
        return tuple(part for part, (targets, triggers) in self._yield_to.items()
                     if any(t.away() for t in targets) or any(tr.level(t_ns) > 0.0 for tr in triggers))

    def idle_yields(self) -> tuple[str, ...]:
        """The idle parts left to the channels and triggers at the last timed ``pose``."""
        return self._yielded

    def _strengths(self, targets, extra: dict[int, float]) -> list[tuple[float, int]]:
        """(strength 0..63, select) per distinct select, strongest first (ties: target order, then
        the triggers'): the targets' values plus ``extra``, the triggers' strengths."""
        by_key: dict[int, float] = {}
        for t in targets:
            by_key[t.key] = by_key.get(t.key, 0.0) + t.evaluate()
        for key, v in extra.items():
            by_key[key] = by_key.get(key, 0.0) + v
        order = sorted(by_key.items(), key=lambda kv: -kv[1])
        return [(min(v, 63.0), k) for k, v in order] or [(0.0, 0)]

    def _viseme(self, fap: np.ndarray, extra: dict[int, float]) -> tuple:
        ranked = self._strengths(self._visemes, extra)
        w, select = ranked[0]
        for weaker, other in ranked[1:]:
            if weaker > 0.0:
                fap += self._shapes["visemes"][other] * (weaker / 63.0)
        return (select, 0, w) if w > 0.0 else (0, 0, 0.0)

    def _expression(self, fap: np.ndarray, extra: dict[int, float]) -> tuple:
        ranked = self._strengths(self._expressions, extra) + [(0.0, 0)]
        (i1, s1), (i2, s2) = ranked[0], ranked[1]
        for weaker, other in ranked[2:]:
            if weaker > 0.0:
                fap += self._shapes["expressions"][other] * (weaker / 63.0)
        return (s1 if i1 > 0 else 0, i1, s2 if i2 > 0 else 0, i2)

    @property
    def held_values(self) -> int:
        """How many target values came out NaN and were replaced by the target's last good one."""
        return self._guard.count

    @property
    def held_problem(self) -> str | None:
        """What the first such value was (None while there has been none), for a one-line report."""
        return None if self._guard.first is None else f"{self.file}: {self._guard.first}"

    # -- for people --------------------------------------------------------------------------

    def channels(self) -> list[ChannelState]:
        """Every channel: raw value, shaped value and the targets it drives (for a monitor)."""
        return [ChannelState(c.name, c.raw, c.value, tuple(c.targets), None if c.raw is None else (c.raw - c.low) * c.k)
                for c in self._channels.values()]

    @property
    def channel_names(self) -> tuple[str, ...]:
        """Every channel the mapping shapes (``device.channel``), in the file's order."""
        return tuple(self._channels)

    def drives(self, channel: str) -> tuple[set[int], set[str]]:
        """What a channel (``device.channel``) moves: its FAP slots (0-based) and the high-level
        kinds (``viseme``, ``expression``, ``muscle``) among its targets."""
        if channel not in self._channels:
            raise KeyError(f"{self.file}: no channel {channel!r}; channels: {', '.join(self._channels)}")
        c = self._channels[channel]
        slots: set[int] = set()
        kinds: set[str] = set()
        for t in (*self._faps, *self._muscles, *self._visemes, *self._expressions):
            if c in t.sources:
                slots.update(t.slots)
                if t.kind in ("viseme", "expression", "muscle"):
                    kinds.add(t.kind)
        for trigger in self.triggers.by_source.get(channel, ()):
            spec = trigger.spec
            slots.update(number - 1 for number, _ in spec.faps)
            if spec.clip is not None:
                slots.update(int(i) for i in np.flatnonzero(np.any(spec.clip.frames != 0.0, axis=0)))
            kinds.update(k for k in spec.kinds if k in ("viseme", "expression", "muscle"))
        return slots, kinds

    # -- triggers ----------------------------------------------------------------------------

    @property
    def trigger_names(self) -> tuple[str, ...]:
        """The mapping's triggers by name, in the file's order (what ``trigger`` takes)."""
        return self.triggers.names

    def trigger(self, name: str, action: str, t_ns: int) -> None:
        """Press, release or fire (a press and a release at once) the trigger ``name`` at
        ``t_ns``; a ValueError naming the triggers there are for an unknown name or action."""
        self.triggers.act(name, action, t_ns)

    def trigger_states(self, t_ns: int | None = None) -> list[TriggerState]:
        """Every trigger's level at ``t_ns`` and whether it is latched on (for the cockpit)."""
        return self.triggers.states(t_ns)

    def resting(self) -> dict[str, float]:
        """The last raw value of every bipolar channel that has one: where its stick rests when
        the performer lets go (what ``recentre`` takes to undo drift)."""
        return {name: c.raw for name, c in self._channels.items() if c.bipolar and c.raw is not None}

    def recentre(self, centres: dict[str, float]) -> dict[str, float]:
        """Make ``centres`` {channel: raw} the rest points of those bipolar channels; returns the
        ones taken (a centre outside its channel's range is not)."""
        return {name: raw for name, raw in centres.items()
                if name in self._channels and self._channels[name].recentre(raw)}

    def reset(self) -> None:
        """Every channel back to rest (no sample seen, filters empty, buttons released), and
        every trigger (released, unlatched, its pose gone at once)."""
        for c in self._channels.values():
            c.reset()
        self.triggers.reset()
        self._seq = 0

    def snapshot(self) -> dict:
        """The state the fed Samples left (raw and shaped values, filters, buttons, triggers), JSON-able
        and exact: a take keeps it from its first frame, so replaying the take's log from it
        gives the same poses as the live session did."""
        state = {"seq": self._seq, "channels": {name: c.snapshot() for name, c in self._channels.items()},
                 "idle": None if self.idle is None else self.idle.state()}
        if self.triggers:
            state["triggers"] = self.triggers.snapshot()
        return state

    def restore(self, snapshot: dict, recorded: Mapping | None = None) -> None:
        """Take up a ``snapshot`` made by ``recorded`` (default: this mapping): exactly for every
        channel shaped the same in both, and for the others by feeding their last raw input
        again (their filters start settled on it). A re-mapped take starts from where the
        performer's hands were."""
        self.reset()
        self._seq = snapshot["seq"]
        self._restore_idle(snapshot.get("idle"))
        specs = self._specs if recorded is None else recorded._specs
        readings: dict[tuple[int, str], dict[str, float]] = {}
        for name, data in snapshot["channels"].items():
            channel = self._channels.get(name)
            if channel is None:
                continue
            if specs.get(name) == self._specs[name]:
                channel.restore(data)
            elif data["raw"] is not None and data["t_ns"] is not None:
                device, _, source = name.partition(".")
                readings.setdefault((data["t_ns"], device), {})[source] = data["raw"]
        for (t_ns, device), values in sorted(readings.items()):
            self.feed(Sample(t_ns, device, values))
        self.triggers.restore(snapshot.get("triggers"), None if recorded is None else recorded.triggers)

    def _restore_idle(self, state: dict | None) -> None:
        """The recorded idle life's seed and origin, with this mapping's parts (a take without
        one, idle off or made before idle life, gets none: its frames had none)."""
        spec = self.idle_spec
        if state is None or spec is None or not spec.parts:
            self.idle = None
            return
        self.idle = IdleLife(int(state["seed"]), int(state["origin_ns"]), spec.parts)

    def __repr__(self) -> str:
        return (f"Mapping({self.file!r}: {len(self.devices)} devices, {len(self._channels)} channels, "
                f"{len(self._faps) + len(self._muscles) + len(self._visemes) + len(self._expressions)} targets)")
