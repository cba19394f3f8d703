"""Triggers: discrete controls that put a pose on the face -- held, latched, or played once.

A mapping's ``triggers:`` (checked by ``puppet.live.triggercheck``) each name a pose -- an
expression, a viseme, FAPs, muscle contractions, or a span of a recorded take (a ``Clip``) --
and how a press plays it:

* ``hold``: the pose rises over ``attack`` seconds while pressed and falls over ``release``
  seconds when let go;
* ``toggle``: each press latches it on (rising) or off (falling);
* ``oneshot``: each press plays it once: attack, ``hold`` seconds at full, release. A clip
  oneshot plays the take's span from its start, faded in over ``attack`` and out over
  ``release`` so that it ends with the span.

A trigger is pressed by its ``source`` channel (its shaped value reaching ``threshold``, and
released below it: a key, a MIDI note, a gamepad button) or by name (``Triggers.act``: the
control API's press / release / fire; fire is a press and a release at once).

The envelope is a pure function of the presses and the pose time: each press or release at t_e
starts a new straight segment of the trigger's phase p (0 at rest, 1 full) from where the last
one had it at t_e, so the phase never jumps (a release mid-attack falls from where it got to)
and the level, ``strength * ease(p)`` (``ease`` linear, or smoothstep 3p^2 - 2p^3), is the same
whoever asks at whatever time. Presses happen at Sample timestamps (or the API call's), so a take
written from the live loop and its rebuild from the log (``puppet.live.retake``) are identical.

Triggers add to the pose the mapping's targets make: an expression's or viseme's strength
(``63 * level``) joins its targets' in the FAP 1 / 2 ranking of ``puppet.live.channels``; FAPs,
muscles and clips add their values times the level.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field

import numpy as np

MODES = ("hold", "toggle", "oneshot")
ACTIONS = ("press", "release", "fire")
EASES = ("smooth", "linear")
NS = 1_000_000_000

_REST, _RISE, _FALL, _SHOT = "rest", "rise", "fall", "shot"


@dataclass(frozen=True)
class Clip:
    """A span of a recorded take: its low-level FAPs (FAP 1 / 2 expanded) per frame at ``fps``,
    from ``start`` to ``end`` seconds of the take (``frames[0]`` is the take's frame at ``start``)."""

    path: str
    start: float
    end: float
    fps: float
    frames: np.ndarray = field(compare=False, repr=False)

    @property
    def seconds(self) -> float:
        return self.end - self.start

    def at(self, seconds: float) -> np.ndarray:
        """The clip's 68 FAP values ``seconds`` after its start (linear between frames, the
        last frame held)."""
        x = seconds * self.fps
        last = len(self.frames) - 1
        if x <= 0.0:
            return self.frames[0]
        if x >= last:
            return self.frames[last]
        i = int(x)
        f = x - i
        return self.frames[i] if f == 0.0 else self.frames[i] + f * (self.frames[i + 1] - self.frames[i])


@dataclass(frozen=True)
class TriggerSpec:
    """One trigger as its mapping wrote it (checked): what it shows, what presses it, how it plays."""

    name: str
    mode: str
    source: str | None = None
    threshold: float = 0.5
    attack: float = 0.1
    release: float = 0.2
    hold: float = 0.0
    ease: str = "smooth"
    strength: float = 1.0
    expression: int | None = None
    viseme: int | None = None
    faps: tuple[tuple[int, float], ...] = ()        # (FAP number 3-68, FAPU)
    muscles: tuple[tuple[str, float], ...] = ()     # (muscle, contraction)
    clip: Clip | None = None

    @property
    def kinds(self) -> tuple[str, ...]:
        """What it moves: ``expression``, ``viseme``, ``fap``, ``muscle``, ``clip``."""
        return tuple(k for k, v in (("expression", self.expression), ("viseme", self.viseme), ("fap", self.faps),
                                    ("muscle", self.muscles), ("clip", self.clip)) if v)


@dataclass(frozen=True)
class TriggerState:
    """What the cockpit shows of one trigger: its level (0..strength) and whether it is on."""

    name: str
    mode: str
    source: str | None
    level: float
    strength: float
    latched: bool

    @property
    def active(self) -> bool:
        return self.level > 0.0 or self.latched


class Trigger:
    """One trigger's envelope: the straight phase segment since its last press or release."""

    __slots__ = ("attack", "down", "fap", "latched", "motion", "p0", "release", "shot_ns", "spec", "t_ns")

    def __init__(self, spec: TriggerSpec) -> None:
        self.spec = spec
        self.attack, self.release = spec.attack, spec.release
        fap = np.zeros(68)
        for number, value in spec.faps:
            fap[number - 1] += value
        self.fap = fap if spec.faps else None
        self.reset()

    def reset(self) -> None:
        self.t_ns, self.p0, self.motion = 0, 0.0, _REST
        self.latched = self.down = False
        self.shot_ns: int | None = None

    # -- the envelope --------------------------------------------------------------------------

    def phase(self, t_ns: int) -> float:
        """The phase, 0 (rest) .. 1 (full), at ``t_ns`` (no earlier than the last press or release)."""
        motion = self.motion
        if motion == _REST:
            return 0.0
        dt = (t_ns - self.t_ns) / NS if t_ns > self.t_ns else 0.0
        p0 = self.p0
        if motion == _RISE:
            return 1.0 if self.attack <= 0.0 else min(1.0, p0 + dt / self.attack)
        if motion == _FALL:
            return 0.0 if self.release <= 0.0 else max(0.0, p0 - dt / self.release)
        rise = (1.0 - p0) * self.attack
        if dt < rise:
            return p0 + dt / self.attack
        dt -= rise
        if dt < self.spec.hold:
            return 1.0
        dt -= self.spec.hold
        return 0.0 if self.release <= 0.0 else max(0.0, 1.0 - dt / self.release)

    def level(self, t_ns: int) -> float:
        p = self.phase(t_ns)
        if self.spec.ease == "smooth":
            p = p * p * (3.0 - 2.0 * p)
        return self.spec.strength * p

    def _move(self, motion: str, t_ns: int) -> None:
        self.p0 = self.phase(t_ns)
        self.t_ns = max(t_ns, self.t_ns)
        self.motion = motion

    # -- presses -------------------------------------------------------------------------------

    def press(self, t_ns: int) -> None:
        mode = self.spec.mode
        if mode == "hold":
            self._move(_RISE, t_ns)
        elif mode == "toggle":
            self.latched = not self.latched
            self._move(_RISE if self.latched else _FALL, t_ns)
        else:
            self._move(_SHOT, t_ns)
            self.shot_ns = self.t_ns

    def let_go(self, t_ns: int) -> None:
        if self.spec.mode == "hold":
            self._move(_FALL, t_ns)

    def act(self, action: str, t_ns: int) -> None:
        """``press``, ``release`` or ``fire`` (a press and a release at once)."""
        if action in ("press", "fire"):
            self.press(t_ns)
        if action in ("release", "fire"):
            self.let_go(t_ns)

    def input(self, value: float, t_ns: int) -> None:
        """Its source channel's new shaped value: a press when it reaches the threshold, a
        release when it drops below."""
        down = value >= self.spec.threshold
        if down != self.down:
            self.down = down
            if down:
                self.press(t_ns)
            else:
                self.let_go(t_ns)

    # -- what it adds --------------------------------------------------------------------------

    def clip_at(self, t_ns: int) -> np.ndarray:
        """The clip's FAPs where the last fire has it at ``t_ns``."""
        shot = self.shot_ns if self.shot_ns is not None else t_ns
        return self.spec.clip.at((t_ns - shot) / NS if t_ns > shot else 0.0)

    _STATE = ("t_ns", "p0", "motion", "latched", "down", "shot_ns")

    def snapshot(self) -> dict:
        return {key: getattr(self, key) for key in self._STATE}

    def restore(self, data: dict) -> None:
        for key in self._STATE:
            setattr(self, key, data[key])


class Triggers:
    """A mapping's triggers: pressed by their channels or by name, added to its poses."""

    def __init__(self, specs: list[TriggerSpec] | tuple[TriggerSpec, ...], file: str = "<mapping>") -> None:
        self.file = file
        self.specs = {spec.name: spec for spec in specs}
        self.all = {name: Trigger(spec) for name, spec in self.specs.items()}
        self.by_source: dict[str, tuple[Trigger, ...]] = {}
        for trigger in self.all.values():
            source = trigger.spec.source
            if source is not None:
                self.by_source[source] = self.by_source.get(source, ()) + (trigger,)
        self.expressions = tuple(t for t in self.all.values() if t.spec.expression)
        self.visemes = tuple(t for t in self.all.values() if t.spec.viseme)
        self.faps = tuple(t for t in self.all.values() if t.fap is not None)
        self.muscled = tuple(t for t in self.all.values() if t.spec.muscles)
        self.clips = tuple(t for t in self.all.values() if t.spec.clip is not None)
        self.muscle_names = tuple(dict.fromkeys(m for t in self.muscled for m, _ in t.spec.muscles))
        self.latest_ns = 0

    def __bool__(self) -> bool:
        return bool(self.all)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.all)

    def check(self, name: str, action: str) -> Trigger:
        """The trigger ``name``, if ``action`` is one it takes; a ValueError saying what exists."""
        if action not in ACTIONS:
            raise ValueError(f"trigger action {action!r}: expected one of {', '.join(ACTIONS)}")
        if name not in self.all:
            if not self.all:
                raise ValueError(f"{self.file}: no trigger {name!r}: this mapping has no triggers")
            close = difflib.get_close_matches(str(name), list(self.all), n=1, cutoff=0.5)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ValueError(f"{self.file}: no trigger {name!r}: expected one of {', '.join(self.all)}{hint}")
        return self.all[name]

    def act(self, name: str, action: str, t_ns: int) -> None:
        """Press, release or fire the trigger ``name`` at ``t_ns`` (a ValueError for an unknown one)."""
        self.check(name, action).act(action, t_ns)
        self.latest_ns = max(self.latest_ns, t_ns)

    def input(self, source: str, value: float, t_ns: int) -> None:
        """Channel ``source``'s new shaped value (at a Sample's time)."""
        for trigger in self.by_source.get(source, ()):
            trigger.input(value, t_ns)
        self.latest_ns = max(self.latest_ns, t_ns)

    def add(self, t_ns: int | None, fap: np.ndarray, muscles: dict[str, float],
            expressions: dict[int, float], visemes: dict[int, float]) -> None:
        """Add every trigger's pose at ``t_ns`` (None: at the latest press or input) into the
        pose being made: ``fap`` and ``muscles`` in place, and the expression and viseme
        strengths (select -> 0..63) the FAP 1 / 2 ranking adds to its targets'."""
        t = self.latest_ns if t_ns is None else t_ns
        for trigger in self.expressions:
            if (v := trigger.level(t)) > 0.0:
                key = trigger.spec.expression
                expressions[key] = expressions.get(key, 0.0) + 63.0 * v
        for trigger in self.visemes:
            if (v := trigger.level(t)) > 0.0:
                key = trigger.spec.viseme
                visemes[key] = visemes.get(key, 0.0) + 63.0 * v
        for trigger in self.faps:
            if (v := trigger.level(t)) > 0.0:
                fap += trigger.fap * v
        for trigger in self.muscled:
            if (v := trigger.level(t)) > 0.0:
                for name, c in trigger.spec.muscles:
                    muscles[name] += c * v
        for trigger in self.clips:
            if (v := trigger.level(t)) > 0.0:
                fap += trigger.clip_at(t) * v

    def states(self, t_ns: int | None = None) -> list[TriggerState]:
        """Every trigger's level at ``t_ns`` (None: at the latest press or input), for the cockpit."""
        t = self.latest_ns if t_ns is None else t_ns
        return [TriggerState(name, tr.spec.mode, tr.spec.source, tr.level(t), tr.spec.strength, tr.latched)
                for name, tr in self.all.items()]

    def reset(self) -> None:
        """Every trigger at rest, released and unlatched (the neutral key)."""
        for trigger in self.all.values():
            trigger.reset()

    def snapshot(self) -> dict:
        return {"latest_ns": self.latest_ns, "each": {name: t.snapshot() for name, t in self.all.items()}}

    def restore(self, data: dict | None, recorded: Triggers | None = None) -> None:
        """Take up a ``snapshot`` made by ``recorded`` (default: these triggers): each trigger
        that both have with the same spec takes its state; the others start at rest."""
        self.reset()
        if not data:
            return
        self.latest_ns = data["latest_ns"]
        specs = self.specs if recorded is None else recorded.specs
        for name, state in data["each"].items():
            if name in self.all and specs.get(name) == self.specs[name]:
                self.all[name].restore(state)
