"""The checks of a mapping's ``triggers:`` section, done by the mapping checker (``puppet.live.mappingfile``).

``triggers`` is a list of triggers, each with its ``name``, or a mapping of name -> trigger::

    triggers:
      smile: {source: keys.1, mode: hold, expression: joy, attack: 0.15, release: 0.3}
      wow: {source: pad.note60, mode: oneshot, expression: surprise, attack: 0.1, hold: 0.5, release: 0.4}
      nod: {source: keys.2, mode: oneshot, clip: {take: takes/nod_001, from: 0.5, to: 2.0}}
      grin: {mode: toggle, faps: {stretch_l_cornerlip: 120, stretch_r_cornerlip: 120}}

The pose uses the targets' words: ``expression`` (name or 1-6), ``viseme`` (1-14), ``faps``
(FAP name or number 3-68 -> FAPU), ``muscles`` (muscle -> contraction 0..1); or, for a oneshot
only, ``clip``: a take folder or .fap file (relative to the mapping file), played from ``from``
to ``to`` seconds (default: the whole take). What the schema cannot say is checked here too: a
source naming a declared channel, names given once, ``hold`` only on an expression oneshot, a
clip's span inside its take and longer than its attack and release. Every problem names the
file, line and key path, with the closest valid name.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from puppet.errors import PuppetError
from puppet.fap.held import held_low_level
from puppet.io.fapfile import iter_fap
from puppet.io.takes import take_fap
from puppet.live.triggers import EASES, MODES, Clip, TriggerSpec

POSE_KEYS = ("expression", "viseme", "faps", "muscles", "clip")
TRIGGER_KEYS = ("name", "source", "mode", "threshold", *POSE_KEYS, "strength", "attack", "release", "hold",
                "ease", "description")
CLIP_KEYS = ("take", "from", "to")
DEFAULT_TIMES = {"attack": 0.1, "release": 0.2, "hold": 0.5}
"""Seconds a pose takes to rise, to fall, and a oneshot stays at full, unless the trigger says;
a clip plays as recorded (no attack or release) unless it says."""
TIME_LIMIT = 600.0      # seconds: the longest attack, release, hold or clip
VALUE_LIMIT = 1e6       # largest FAP value a trigger may add (FAPU), as a target's range
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*\Z")


def check_triggers(check, value, channels: dict, file: str) -> list[TriggerSpec]:
    """The triggers of a mapping (``value``: the ``triggers`` section), checked by ``check``
    (the mapping's ``_Checker``: its problems, lines and target words); ``file`` is the mapping
    file, which clip paths are relative to."""
    path = ("triggers",)
    if isinstance(value, list):
        items = []
        for i, spec in enumerate(value):
            if not isinstance(spec, dict):
                check.expect(path + (i,), "a trigger (a mapping with name, mode and a pose)", spec)
            elif "name" not in spec:
                check.error(path + (i,), "missing key 'name': a trigger in a list needs a name")
            else:
                items.append((path + (i,), spec["name"], spec))
    elif isinstance(value, dict):
        items = [(path + (name,), name, spec) for name, spec in value.items()]
    else:
        check.expect(path, "a list of triggers or a mapping of trigger name -> trigger", value)
        return []
    out, seen = [], {}
    for where, name, spec in items:
        at = where + ("name",) if isinstance(value, list) else where
        if not isinstance(name, str) or not NAME.match(name):
            check.expect(at, "a trigger name of letters, digits, '_' and '-'", name)
            continue
        if name in seen:
            check.error(at, f"trigger {name!r} is defined twice (first at {seen[name]}): expected each name once")
            continue
        seen[name] = ".".join(map(str, where))
        if isinstance(value, dict) and isinstance(spec, dict) and "name" in spec:
            check.error(where + ("name",), f"a trigger under its name needs no name key (it is {name!r})")
            continue
        trigger = _trigger(check, where, name, spec, channels, file)
        if trigger is not None:
            out.append(trigger)
    return out


def _trigger(check, where: tuple, name: str, spec, channels: dict, file: str) -> TriggerSpec | None:
    spec = check.mapping(where, spec, TRIGGER_KEYS, f"trigger {name!r}", required=("mode",))
    if spec is None or "mode" not in spec:
        return None
    before = len(check.problems)
    mode = check.choice(where + ("mode",), spec["mode"], MODES, "a trigger mode")
    source = None
    if "source" in spec:
        if isinstance(spec["source"], str):
            found = check.sources(where + ("source",), spec["source"], channels)
            source = found[0] if found else None
        else:
            check.expect(where + ("source",), "one source channel device.channel (e.g. keys.1)", spec["source"])
    threshold = 0.5
    if "threshold" in spec:
        threshold = check.number(where + ("threshold",), spec["threshold"], -1.0, 1.0,
                                 expected="a number from -1 to 1 (the source's shaped value that presses it)")
        if "source" not in spec:
            check.error(where + ("threshold",), "threshold applies to a trigger with a source: expected a "
                                                "source with it, or no threshold")
    poses = [k for k in POSE_KEYS if k in spec]
    if not poses:
        check.error(where, f"expected a pose in trigger {name!r}: one or more of expression, viseme, faps, "
                           "muscles, or a clip")
    elif "clip" in poses and len(poses) > 1:
        check.error(where + ("clip",), f"a clip plays alone: expected no {', '.join(p for p in poses if p != 'clip')} "
                                       "with a clip")
    expression = check.target_key(where + ("expression",), "expression", spec["expression"]) \
        if "expression" in spec else None
    viseme = check.target_key(where + ("viseme",), "viseme", spec["viseme"]) if "viseme" in spec else None
    faps = _faps(check, where + ("faps",), spec["faps"]) if "faps" in spec else ()
    muscles = _muscles(check, where + ("muscles",), spec["muscles"]) if "muscles" in spec else ()
    clip = _clip(check, where + ("clip",), spec["clip"], file) if "clip" in spec else None
    if "clip" in spec and mode not in (None, "oneshot"):
        check.error(where + ("clip",), f"a clip plays once: expected mode: oneshot with a clip, got mode: {mode}")
    strength = check.number(where + ("strength",), spec["strength"], 0.0, 1.0, low_open=True,
                            expected="a number > 0 and <= 1 (the fraction of the pose at full)") \
        if "strength" in spec else 1.0
    zero = "clip" in spec
    times = {}
    for key in ("attack", "release"):
        times[key] = check.number(where + (key,), spec[key], 0.0, TIME_LIMIT,
                                  expected=f"seconds from 0 to {TIME_LIMIT:g}") \
            if key in spec else (0.0 if zero else DEFAULT_TIMES[key])
    hold = 0.0
    if "hold" in spec:
        if mode != "oneshot" or zero:
            check.error(where + ("hold",), "hold is how long a oneshot stays at full: expected it only on a "
                                           "oneshot that is no clip (a clip's span is its length)")
        else:
            hold = check.number(where + ("hold",), spec["hold"], 0.0, TIME_LIMIT,
                                expected=f"seconds from 0 to {TIME_LIMIT:g}")
    elif mode == "oneshot" and not zero:
        hold = DEFAULT_TIMES["hold"]
    if clip is not None and None not in times.values():
        hold = clip.seconds - times["attack"] - times["release"]
        if hold < 0.0:
            check.error(where, f"attack + release ({times['attack'] + times['release']:g} s) is longer than the "
                               f"clip ({clip.seconds:g} s): expected them to fit in it")
    ease = check.choice(where + ("ease",), spec["ease"], EASES, "an ease") if "ease" in spec else "smooth"
    if "description" in spec:
        check.string(where + ("description",), spec["description"])
    if len(check.problems) > before or None in (mode, threshold, strength, hold, ease, *times.values()):
        return None
    return TriggerSpec(name, mode, source, threshold, times["attack"], times["release"], hold, ease, strength,
                       expression, viseme, faps, muscles, clip)


def _faps(check, where: tuple, value) -> tuple[tuple[int, float], ...]:
    if not isinstance(value, dict) or not value:
        check.expect(where, "a mapping of FAP name or number 3-68 -> value in FAPU (e.g. {open_jaw: 300})", value)
        return ()
    out = []
    for key, v in value.items():
        number = check.target_key(where + (key,), "fap", key)
        amount = check.number(where + (key,), v, -VALUE_LIMIT, VALUE_LIMIT,
                              expected=f"a value in FAPU from {-VALUE_LIMIT:g} to {VALUE_LIMIT:g}")
        if number is not None and amount is not None:
            out.append((number, amount))
    return tuple(out)


def _muscles(check, where: tuple, value) -> tuple[tuple[str, float], ...]:
    if not isinstance(value, dict) or not value:
        check.expect(where, "a mapping of muscle -> contraction 0..1 (e.g. {zygomatic_major_l: 0.8})", value)
        return ()
    out = []
    for key, v in value.items():
        muscle = check.target_key(where + (key,), "muscle", key)
        amount = check.number(where + (key,), v, 0.0, 1.0, expected="a contraction from 0 to 1")
        if muscle is not None and amount is not None:
            out.append((muscle, amount))
    return tuple(out)


def _clip(check, where: tuple, value, file: str) -> Clip | None:
    spec = check.mapping(where, value, CLIP_KEYS, "a clip", required=("take",))
    if spec is None or "take" not in spec or check.string(where + ("take",), spec["take"]) is None:
        return None
    start = check.number(where + ("from",), spec["from"], 0.0, TIME_LIMIT,
                         expected=f"seconds into the take from 0 to {TIME_LIMIT:g}") if "from" in spec else 0.0
    end = check.number(where + ("to",), spec["to"], 0.0, TIME_LIMIT, low_open=True,
                       expected=f"seconds into the take > 0 and <= {TIME_LIMIT:g}") if "to" in spec else None
    if start is None or ("to" in spec and end is None):
        return None
    if end is not None and not end > start:
        check.error(where + ("to",), f"expected to after from ({start:g} s), got {end:g}")
        return None
    taken = Path(spec["take"])
    path = taken if taken.is_absolute() else Path(file).parent / taken
    try:
        fap = take_fap(path)
        with iter_fap(fap) as reader:
            fps = reader.header.fps
            frames = np.array(list(held_low_level(reader)))
    except (PuppetError, OSError) as exc:
        reason = f"{path}: {exc.strerror}" if isinstance(exc, OSError) and exc.strerror else str(exc)
        check.error(where + ("take",), f"{reason} (a clip's take is found relative to the mapping file)")
        return None
    length = (len(frames) - 1) / fps if len(frames) else 0.0
    end = length if end is None else end
    if len(frames) < 2 or end > length + 0.5 / fps or not end > start:
        check.error(where + ("to" if "to" in spec else "take",),
                    f"expected a span inside the take ({len(frames)} frames at {fps:g} fps: 0 to {length:g} s), "
                    f"got {start:g} to {end:g} s")
        return None
    first, last = round(start * fps), min(round(end * fps), len(frames) - 1)
    span = frames[first:last + 1].copy()
    span.flags.writeable = False
    return Clip(str(path), start, end, fps, span)
