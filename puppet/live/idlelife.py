"""Idle life: the blinks, small eye movements and breathing a face makes when no channel drives them.

A face that holds perfectly still while the performer's hands rest looks dead; every VTuber tool
blinks on its own. ``IdleLife(seed, origin_ns)`` is a *pure function* of time: ``offsets(t_ns)``
gives the FAP offsets at any times, the same for the same seed, origin and time whatever the
order or rate of the calls, so a live take, its rebuild (``puppet.live.retake``) and a replay
through the devices agree to the byte. Before ``origin_ns`` (the moment the mapping was loaded,
in a live session) the face is at rest. Each part's events (blinks, saccades) are drawn from its
own random stream, in fixed-size chunks as far ahead as asked: the k-th event is the same
however far the schedule was drawn before.

Blinks (FAPs 19-22, ``close_t_l/r_eyelid``, ``close_b_l/r_eyelid``), from measurements of people
at rest (the figures of the project's reference notes, ``shared/reference/LIVE-FACTS.md``):

* rate: 17 a minute on average (Bentivoglio et al., *Movement Disorders* 12(6), 1997: 150
  adults, 17/min at rest, 26 in conversation, 4.5 reading). Intervals are irregular, not
  periodic; here they are log-normal (median ``BLINK_MEDIAN_S``, log-sd ``BLINK_SIGMA``, mean
  60/17 s), never shorter than ``BLINK_MIN_GAP_S`` so two blinks never overlap;
* shape: a blink closes fast and opens more slowly, 1:2 to 1:3, and lasts a few hundred
  milliseconds (Evinger, Manning & Sibony, "Eyelid movements: mechanisms and normal data",
  IOVS 32(2), 1991): closing 80-110 ms, held shut 20-60 ms, opening 2-3 times the closing, so a
  blink lasts 260-500 ms;
* asymmetry: the upper lid does nearly all the moving (same source): at the peak the upper lids
  drop 800 IRISD and the lower ones rise 224 (78% / 22%), the split with which the default face's
  lids meet along their whole length with nothing folding (``puppet.runtime.lidclosure``: 0.5%
  of the opening left).

Eyes (FAPs 23-26, both eyes together): at rest the eyes make small saccades, under 1 degree, and
drift between them (Martinez-Conde, Macknik & Hubel, Nat. Rev. Neurosci. 5, 2004), and gaze shifts
come with a blink more often than chance (Evinger et al., Exp. Brain Res. 100, 1994).
Gaze jumps every 1-3 s (uniform), and in ``BLINK_GAZE_SHIFT`` of the blinks while the lids are
shut, to a point drawn in a disc of radius ``SACCADE_RADIUS_DEG`` around straight ahead (so every
jump is under 1 degree), in ``SACCADE_S`` (a small saccade's duration on the main sequence,
about 20-30 ms), and drifts between jumps as two slow sines per axis of about ``DRIFT_DEG``.

Breath (FAP 48, head pitch, and FAPs 61/62, the nostrils): an adult at rest breathes 12-20 times
a minute (the clinical resting range of the vital signs); the rate is drawn per seed in 12-16,
with a slow wobble of its phase. Inhaling (40% of the cycle) lifts the head ``BREATH_PITCH_DEG``
and flares the nostrils ``NOSTRIL_ENS``; exhaling (60%) lets them back. Subtle on purpose.

``offsets`` is vectorised over times (a 10-minute take's 18,000 frames in one call); a live frame
asks for one time (``add_to``): plain floats, ``bisect`` and ``math``, about 5 us (numpy's
per-call overhead on one-element arrays cost 20 times that). Both give the same values.
"""

from __future__ import annotations

import bisect
import math
import secrets
import threading
from dataclasses import dataclass

import numpy as np

from puppet.fap.table import N_FAPS
from puppet.fap.units import AU

PARTS = ("blink", "eyes", "breath")
PART_FAPS = {"blink": (19, 20, 21, 22), "eyes": (23, 24, 25, 26), "breath": (48, 61, 62)}
"""The FAPs (1-based) each part writes."""

BLINKS_PER_MIN = 17.0            # Bentivoglio et al. 1997, at rest
BLINK_SIGMA = 0.55               # log-sd of the intervals (irregular, right-skewed)
BLINK_MEDIAN_S = 60.0 / BLINKS_PER_MIN / math.exp(BLINK_SIGMA ** 2 / 2)
BLINK_MIN_GAP_S = 0.6            # start to start; longer than the longest blink (0.5 s)
BLINK_CLOSE_S = (0.080, 0.110)   # closing time
BLINK_HOLD_S = (0.020, 0.060)    # shut
BLINK_OPEN_RATIO = (2.0, 3.0)    # opening / closing
LID_UPPER, LID_LOWER = 800.0, 224.0   # IRISD at the peak: the lids meet (puppet.runtime.lidclosure)

BLINK_GAZE_SHIFT = 0.4          # share of blinks the eyes jump in (while shut)
SACCADE_EVERY_S = (1.0, 3.0)
SACCADE_RADIUS_DEG = 0.5
SACCADE_S = 0.025
DRIFT_DEG = 0.08
DRIFT_HZ = (0.05, 0.3)

BREATHS_PER_MIN = (12.0, 16.0)
BREATH_INHALE = 0.4              # share of the cycle
BREATH_PITCH_DEG = 0.25
NOSTRIL_ENS = 12.0

_DEG_TO_AU = math.pi / 180.0 / AU
_CHUNK = 64                      # events drawn at a time, per part
_STREAMS = {"blink": 1, "eyes": 2, "breath": 3}


@dataclass(frozen=True)
class IdleSpec:
    """What a mapping's ``idle:`` key asks for: the parts on, and a seed (None: drawn at load)."""

    blink: bool = True
    eyes: bool = True
    breath: bool = True
    seed: int | None = None

    @property
    def parts(self) -> tuple[str, ...]:
        return tuple(p for p in PARTS if getattr(self, p))


ALL_ON = IdleSpec()
"""A mapping without an ``idle`` key: every part, a seed drawn at load."""


def random_seed() -> int:
    """A seed for a session whose mapping names none (kept in the take's metadata)."""
    return secrets.randbelow(2 ** 31)


def _ease(u: np.ndarray) -> np.ndarray:
    """0 -> 1 with zero speed at both ends (a raised cosine), for u in 0..1."""
    return 0.5 - 0.5 * np.cos(np.pi * u)


def _ease1(u: float) -> float:
    """``_ease`` for one value."""
    return 0.5 - 0.5 * math.cos(math.pi * u)


class _Schedule:
    """A part's events, drawn in chunks of ``_CHUNK`` from its own stream as far ahead as asked.

    Drawing holds ``lock`` (the session's loop and a control API's thread may both ask for a
    pose) and publishes the longer columns before the longer times, so a reader without the
    lock never finds a time without its row; what was drawn never changes."""

    def __init__(self, seed: int, stream: int, draw, lock: threading.RLock) -> None:
        self._rng = np.random.default_rng([seed, stream])
        self._draw = draw          # rng, n -> (gaps s, columns {name: array})
        self._lock = lock
        self.times = np.zeros(0)
        self.columns: dict[str, np.ndarray] = {}

    def cover(self, until_s: float) -> None:
        """Draw until an event lies after ``until_s``."""
        if self.times.size and self.times[-1] > until_s:
            return
        with self._lock:
            while not self.times.size or self.times[-1] <= until_s:
                gaps, drawn = self._draw(self._rng, _CHUNK)
                start = self.times[-1] if self.times.size else 0.0
                columns = {key: np.concatenate([self.columns.get(key, np.zeros(0)), values])
                           for key, values in drawn.items()}
                times = np.concatenate([self.times, start + np.cumsum(gaps)])
                self.columns, self.rows = columns, {key: values.tolist() for key, values in columns.items()}
                self.times, self.starts = times, times.tolist()

    def at(self, s: float) -> int:
        """The last event at or before ``s`` (-1: none yet), for one time (``bisect``, no numpy)."""
        if not self.times.size or self.starts[-1] <= s:
            self.cover(s)
        return bisect.bisect_right(self.starts, s) - 1


def _fixations(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """``n`` points drawn evenly in the disc of radius ``SACCADE_RADIUS_DEG`` (degrees)."""
    r = SACCADE_RADIUS_DEG * np.sqrt(rng.uniform(0.0, 1.0, n))
    a = rng.uniform(0.0, 2 * np.pi, n)
    return {"yaw": r * np.cos(a), "pitch": r * np.sin(a)}


def _draw_blinks(rng: np.random.Generator, n: int):
    gaps = np.maximum(rng.lognormal(math.log(BLINK_MEDIAN_S), BLINK_SIGMA, n), BLINK_MIN_GAP_S)
    close = rng.uniform(*BLINK_CLOSE_S, n)
    hold = rng.uniform(*BLINK_HOLD_S, n)
    opening = close * rng.uniform(*BLINK_OPEN_RATIO, n)
    shift = (rng.uniform(0.0, 1.0, n) < BLINK_GAZE_SHIFT).astype(float)
    return gaps, {"close": close, "hold": hold, "open": opening, "shift": shift, **_fixations(rng, n)}


def _draw_saccades(rng: np.random.Generator, n: int):
    return rng.uniform(*SACCADE_EVERY_S, n), _fixations(rng, n)


class _Gaze:
    """Where the eyes jump: the saccades' own times and, for a share of the blinks, the moment
    the lids are shut, merged in time order (the same interface as ``_Schedule``; column rows
    are fixations, row 0 straight ahead, row k + 1 where event k went). Rebuilt when asked
    beyond what both streams have drawn; an event's fixation is drawn with it, so the merged
    events up to any time are the same however far either stream was drawn."""

    def __init__(self, blinks: _Schedule, saccades: _Schedule, lock: threading.RLock) -> None:
        self._blinks, self._saccades = blinks, saccades
        self._lock = lock
        self.times = np.zeros(0)
        self.columns: dict[str, np.ndarray] = {}
        self.horizon = -1.0          # every event up to here is merged

    def cover(self, until_s: float) -> None:
        if self.horizon > until_s and self.times.size:
            return
        with self._lock:
            while self.horizon <= until_s or not self.times.size:
                self._merge(max(until_s, self.horizon))

    def _merge(self, until_s: float) -> None:
        """Draw both streams past ``until_s`` and merge every event up to where both reach."""
        b, sac = self._blinks, self._saccades
        b.cover(until_s)
        sac.cover(until_s)
        shift = b.columns["shift"] > 0.0
        times = np.concatenate([sac.times, b.times[shift] + b.columns["close"][shift]])
        horizon = min(b.times[-1], sac.times[-1])
        keep = times <= horizon
        order = np.argsort(times[keep], kind="stable")
        columns = {key: np.concatenate([[0.0], np.concatenate([sac.columns[key], b.columns[key][shift]])[keep][order]])
                   for key in ("yaw", "pitch")}
        self.columns, self.rows = columns, {key: values.tolist() for key, values in columns.items()}
        self.times = times[keep][order]
        self.starts = self.times.tolist()
        self.horizon = horizon

    def at(self, s: float) -> int:
        self.cover(s)
        return bisect.bisect_right(self.starts, s) - 1


class IdleLife:
    """The idle motion of one session: ``offsets(t_ns)`` -> FAP offsets (see the module docstring)."""

    def __init__(self, seed: int, origin_ns: int, parts: tuple[str, ...] = PARTS) -> None:
        self.seed, self.origin_ns = int(seed), int(origin_ns)
        self.parts = tuple(p for p in PARTS if p in parts)
        lock = threading.RLock()
        self._blinks = _Schedule(self.seed, _STREAMS["blink"], _draw_blinks, lock)
        self._saccades = _Gaze(self._blinks, _Schedule(self.seed, _STREAMS["eyes"], _draw_saccades, lock), lock)
        rng = np.random.default_rng([self.seed, _STREAMS["breath"], 1])
        self._drift = (rng.uniform(*DRIFT_HZ, (2, 2)), rng.uniform(0, 2 * np.pi, (2, 2)))
        self._drift_rows = (self._drift[0].tolist(), self._drift[1].tolist())
        self._breath_hz = float(rng.uniform(*BREATHS_PER_MIN)) / 60.0
        self._wobble = (float(rng.uniform(0.01, 0.03)), float(rng.uniform(0, 2 * np.pi)))
        self._slots = {part: np.array(PART_FAPS[part]) - 1 for part in PARTS}

    def state(self) -> dict:
        """What a take keeps to make the same motion again (``from_state``)."""
        return {"seed": self.seed, "origin_ns": self.origin_ns, "parts": list(self.parts)}

    def describe(self) -> str:
        """What a performer is told at start: the parts and the seed that makes the motion again."""
        return f"idle life: {', '.join(self.parts)} (seed {self.seed}; the mapping's idle: false turns it off)"

    @classmethod
    def from_state(cls, state: dict, parts: tuple[str, ...] | None = None) -> IdleLife:
        return cls(state["seed"], state["origin_ns"], tuple(state["parts"]) if parts is None else parts)

    # -- the parts, vectorised over times in seconds since the origin (all >= 0) ---------------

    def lids(self, s: np.ndarray) -> np.ndarray:
        """How shut the lids are, 0 (open) .. 1 (shut), at each time."""
        sched = self._blinks
        sched.cover(float(s.max(initial=0.0)))
        i = np.searchsorted(sched.times, s, side="right") - 1
        j = np.maximum(i, 0)
        c, h, o = sched.columns["close"][j], sched.columns["hold"][j], sched.columns["open"][j]
        dt = s - sched.times[j]
        closing = _ease(np.clip(dt / c, 0.0, 1.0))
        opening = 1.0 - _ease(np.clip((dt - c - h) / o, 0.0, 1.0))
        shut = np.where(dt < c + h, closing, opening)
        return np.where(i >= 0, shut, 0.0)

    def gaze(self, s: np.ndarray) -> np.ndarray:
        """(yaw, pitch) in degrees at each time: the fixation the saccades reached, plus drift."""
        sched = self._saccades
        sched.cover(float(s.max(initial=0.0)))
        i = np.searchsorted(sched.times, s, side="right") - 1
        k = i + 1                     # fixation k: straight ahead (0), then where event k-1 went
        before = np.maximum(k - 1, 0)
        u = np.where(i >= 0, _ease(np.clip((s - sched.times[np.maximum(i, 0)]) / SACCADE_S, 0.0, 1.0)), 0.0)
        out = np.empty((2, s.size))
        for axis, key in enumerate(("yaw", "pitch")):
            fix = sched.columns[key]
            out[axis] = fix[before] + (fix[k] - fix[before]) * u
        freqs, phases = self._drift
        out += DRIFT_DEG * np.sin(2 * np.pi * freqs[:, :, None] * s + phases[:, :, None]).sum(axis=1) / 2
        return out

    def breath(self, s: np.ndarray) -> np.ndarray:
        """How full the breath is, 0 (out) .. 1 (in), at each time."""
        depth, phase0 = self._wobble
        cycles = self._breath_hz * s + depth * np.sin(2 * np.pi * 0.02 * s + phase0)
        u = cycles - np.floor(cycles)
        return np.where(u < BREATH_INHALE, _ease(u / BREATH_INHALE),
                        1.0 - _ease((u - BREATH_INHALE) / (1.0 - BREATH_INHALE)))

    def part(self, name: str, s: np.ndarray) -> np.ndarray:
        """A part's FAP values (columns: ``PART_FAPS[name]``) at times ``s`` (seconds since the origin)."""
        if name == "blink":
            lid = self.lids(s)
            return np.stack([lid * LID_UPPER, lid * LID_UPPER, lid * LID_LOWER, lid * LID_LOWER], axis=1)
        if name == "eyes":
            yaw, pitch = self.gaze(s) * _DEG_TO_AU
            return np.stack([yaw, yaw, pitch, pitch], axis=1)
        b = self.breath(s)
        return np.stack([-BREATH_PITCH_DEG * _DEG_TO_AU * b, NOSTRIL_ENS * b, NOSTRIL_ENS * b], axis=1)

    # -- FAP offsets --------------------------------------------------------------------------

    def offsets(self, t_ns, parts: tuple[str, ...] | None = None) -> np.ndarray:
        """(n, 68) FAP offsets at times ``t_ns`` (monotonic ns; before the origin: zeros)."""
        t = np.atleast_1d(np.asarray(t_ns, dtype=np.int64))
        s = np.maximum(t - self.origin_ns, 0) / 1e9
        out = np.zeros((t.size, N_FAPS))
        for name in self.parts if parts is None else parts:
            out[:, self._slots[name]] = self.part(name, s)
        out[t < self.origin_ns] = 0.0
        return out

    def add_to(self, fap: np.ndarray, t_ns: int, skip: tuple[str, ...] = ()) -> None:
        """Add the offsets at ``t_ns`` of every part not in ``skip`` to ``fap`` (68 values), in
        place: the live frame's path, one time in plain floats (``offsets`` gives the same values
        to within rounding; the live session and a retake both come here, so takes are exact)."""
        if t_ns < self.origin_ns:
            return
        s = (t_ns - self.origin_ns) / 1e9
        if "blink" in self.parts and "blink" not in skip:
            lid = self._lid(s)
            if lid:
                fap[18] += lid * LID_UPPER
                fap[19] += lid * LID_UPPER
                fap[20] += lid * LID_LOWER
                fap[21] += lid * LID_LOWER
        if "eyes" in self.parts and "eyes" not in skip:
            yaw, pitch = self._gaze(s)
            fap[22] += yaw * _DEG_TO_AU
            fap[23] += yaw * _DEG_TO_AU
            fap[24] += pitch * _DEG_TO_AU
            fap[25] += pitch * _DEG_TO_AU
        if "breath" in self.parts and "breath" not in skip:
            b = self._breath(s)
            fap[47] += -BREATH_PITCH_DEG * _DEG_TO_AU * b
            fap[60] += NOSTRIL_ENS * b
            fap[61] += NOSTRIL_ENS * b

    def _lid(self, s: float) -> float:
        sched = self._blinks
        i = sched.at(s)
        if i < 0:
            return 0.0
        c, h, o = sched.rows["close"][i], sched.rows["hold"][i], sched.rows["open"][i]
        dt = s - sched.starts[i]
        if dt < c + h:
            return _ease1(min(dt / c, 1.0))
        return 1.0 - _ease1(min((dt - c - h) / o, 1.0))

    def _gaze(self, s: float) -> tuple[float, float]:
        sched = self._saccades
        i = sched.at(s)
        u = 0.0 if i < 0 else _ease1(min((s - sched.starts[i]) / SACCADE_S, 1.0))
        k, before = i + 1, max(i, 0)
        out = []
        for axis, key in enumerate(("yaw", "pitch")):
            fix = sched.rows[key]
            (f1, f2), (p1, p2) = self._drift_rows[0][axis], self._drift_rows[1][axis]
            drift = DRIFT_DEG * (math.sin(2 * math.pi * f1 * s + p1) + math.sin(2 * math.pi * f2 * s + p2)) / 2
            out.append(fix[before] + (fix[k] - fix[before]) * u + drift)
        return out[0], out[1]

    def _breath(self, s: float) -> float:
        depth, phase0 = self._wobble
        cycles = self._breath_hz * s + depth * math.sin(2 * math.pi * 0.02 * s + phase0)
        u = cycles - math.floor(cycles)
        if u < BREATH_INHALE:
            return _ease1(u / BREATH_INHALE)
        return 1.0 - _ease1((u - BREATH_INHALE) / (1.0 - BREATH_INHALE))
