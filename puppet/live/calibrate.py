"""``puppet calibrate``: measure a mapping's controls and write their raw ranges back into its YAML.

Two timed recordings, each started when the user presses Enter:

1. **rest** (``rest_seconds``): every control left alone. A channel's ``centre`` is the *median*
   of its rest samples (robust against a stray spike); the rest samples' own spread (0.5th to
   99.5th percentile) is the channel's noise.
2. **sweep** (``sweep_seconds``): every control moved through its whole travel. ``min`` / ``max``
   are the **0.5th / 99.5th percentiles** of the sweep samples (linear interpolation), not the
   true extremes: one glitched reading does not stretch the range, and a control held at an end
   stop for any time at all still reaches it. A device that reads whole counts (every sample a
   whole number: an ADC) gets whole limits: the min rounded down, the max up, the centre to the
   nearest count.

A channel **never moved** when its sweep span (max - min) is no more than 4x its rest noise (or
exactly 0); one that **never reported** got no sample in either phase. Both are reported with a
warning and left as they are in the file; so is a bipolar channel whose rest median does not lie
strictly inside the swept range (the mapping requires min < centre < max).

The calibration goes back into the YAML in round-trip mode (``ruamel.yaml``): comments, key order,
quoting and indentation are kept; ``min`` and ``max`` are set on every calibrated channel, and
``centre`` on ``range: bipolar`` ones only (a unipolar channel takes no centre); a channel with no
entry under ``channels:`` gets one. The file is replaced atomically (temporary file + rename) after
the original is copied to ``<file>.bak``; the result is loaded again with ``load_mapping`` and, if
that fails, the backup is put back and ``CalibrationError`` raised.

Devices come from ``Mapping.devices`` through ``open_device`` (started here and closed at the
end), unless ``devices={name: Device}`` is given: those are started (if they are not already) and
left open for the caller to close.
"""

from __future__ import annotations

import io
import math
import os
import re
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from collections.abc import Mapping as MappingABC
from pathlib import Path
from typing import TextIO

import numpy as np

from devices import Device, open_device
from devices.base import State
from puppet.errors import PuppetError
from puppet.live.mappingfile import MappingError, Problem, load_mapping

LOW_PCT, HIGH_PCT = 0.5, 99.5     # robust extremes of the sweep (and of the rest noise)
NOISE_FACTOR = 4.0                 # a sweep span within this many rest-noise spans "never moved"
POLL = 0.01                        # seconds between drains while recording
ANSWER_SECONDS = 3.0               # every device must be open this long after it starts
READY_SECONDS = 2.0                # the window's calibration: time to let go, and to get ready to sweep


class CalibrationError(PuppetError, RuntimeError):
    """Calibration could not be written (the file would not load, or could not be replaced)."""


def _ask(prompt: Callable[[str], object], text: str) -> None:
    """Wait for Enter; a stdin that ends or is gone is a CalibrationError, not a traceback."""
    try:
        prompt(text)
    except EOFError:
        raise CalibrationError("stdin ended before Enter was pressed: calibrate needs a terminal") from None
    except RuntimeError as error:  # input(): lost sys.stdin
        raise CalibrationError(f"calibrate needs a terminal on stdin ({error})") from None


def calibrate(mapping_path: str | os.PathLike, *, rest_seconds: float = 2.0, sweep_seconds: float = 8.0,
              devices: MappingABC[str, Device] | None = None, urls: MappingABC[str, str] | None = None,
              prompt: Callable[[str], object] = input, out: TextIO | None = None) -> dict[str, dict]:
    """Record rest and sweep, report, write min/centre/max into ``mapping_path``.

    ``urls`` opens the mapping's device NAME at another URL (``puppet calibrate --device``).
    Returns ``{channel: {"min", "centre", "max", "samples"}}`` for every channel of the mapping
    (raw units; None where the channel never reported; ``samples`` counts both phases). Raises
    ``MappingError`` for a mapping that does not load or a ``urls`` name it has no device for
    (before any device opens), ``DeviceError`` for a device that cannot be opened,
    ``CalibrationError`` for a device that is not open within ``ANSWER_SECONDS`` (with the
    reason) or when the written file would not load (the original is restored).
    """
    out = sys.stdout if out is None else out
    path = Path(mapping_path)
    mapping = load_mapping(path)
    device_urls = device_overrides(path, mapping.devices, urls or {})
    if prompt is input and (sys.stdin is None or sys.stdin.closed):
        raise CalibrationError("calibrate asks you to press Enter before each step: it needs a terminal"
                               " on stdin, which is closed")
    channels = calibration_channels(mapping)
    wanted: dict[str, dict[str, str]] = {}  # device -> {channel key in Sample.values: channel name}
    for name in channels:
        device, key = name.split(".", 1)
        wanted.setdefault(device, {})[key] = name

    opened: dict[str, Device] = {}
    try:
        if devices is None:
            for name, url in device_urls.items():
                opened[name] = open_device(url, name)
            live = dict(opened)
        else:
            live = dict(devices)
        missing = sorted(set(wanted) - set(live))
        if missing:
            raise CalibrationError(f"{path}: no device given for {', '.join(missing)}")
        for device in live.values():
            device.start()
        _wait_answering(live, device_urls)

        print(f"Calibrating {path} ({len(channels)} channels on {len(live)} device(s)).", file=out)
        print("Step 1/2: leave every control at rest.", file=out)
        _ask(prompt, f"Press Enter, then keep still for {rest_seconds:g} s... ")
        rest = _record(live, wanted, rest_seconds)
        print("Step 2/2: move every control through its full range, end to end, a few times.", file=out)
        _ask(prompt, f"Press Enter, then sweep for {sweep_seconds:g} s... ")
        sweep = _record(live, wanted, sweep_seconds)
    finally:
        for device in opened.values():
            device.close()

    result, updates, warnings = _analyse(channels, rest, sweep)
    _report(result, warnings, out)
    if updates:
        write_calibration(path, updates)
        print(f"Wrote {len(updates)} channel(s) to {path} (backup: {path}.bak).", file=out)
    else:
        print(f"Nothing calibrated; {path} left unchanged.", file=out)
    return result


def device_overrides(path: str | os.PathLike, devices: MappingABC[str, str],
                     urls: MappingABC[str, str]) -> dict[str, str]:
    """The mapping's ``devices`` (name -> URL) with ``urls`` put in by name; a name the mapping has
    no device for is a ``MappingError`` naming the ones it has."""
    unknown = sorted(set(urls) - set(devices))
    if unknown:
        raise MappingError(str(path), [Problem("devices", None, f"no device named {', '.join(map(repr, unknown))} "
                                               f"to open elsewhere (--device); this mapping's devices: "
                                               f"{', '.join(devices) or 'none'}")])
    return {**devices, **urls}


def _wait_answering(live: MappingABC[str, Device], urls: MappingABC[str, str]) -> None:
    """Wait up to ``ANSWER_SECONDS`` for every device to be open (a MIDI box at rest sends nothing,
    so readings are not asked for); a CalibrationError naming each one that is not, and why (port
    missing, permission denied, unplugged)."""
    deadline = time.monotonic() + ANSWER_SECONDS
    while time.monotonic() < deadline:
        if all(d.state is State.OPEN for d in live.values()):
            return
        time.sleep(POLL)
    closed = [f"{name} ({urls.get(name, 'given')}): {device.state.value}"
              f"{f' ({device.counters.last_error})' if device.counters.last_error else ''}"
              for name, device in live.items() if device.state is not State.OPEN]
    raise CalibrationError(f"not calibrating: not open after {ANSWER_SECONDS:g} s: {'; '.join(closed)}")


def _record(live: dict[str, Device], wanted: dict[str, dict[str, str]], seconds: float) -> dict[str, list[float]]:
    """Every value of the mapping's channels read during ``seconds`` (what came before is dropped)."""
    values: dict[str, list[float]] = {name: [] for keys in wanted.values() for name in keys.values()}
    for device in live.values():
        device.drain()
    deadline = time.monotonic() + seconds
    while True:
        last = time.monotonic() >= deadline
        for dev_name, device in live.items():
            keys = wanted.get(dev_name, {})
            for sample in device.drain():
                for key, v in sample.values.items():
                    name = keys.get(key)
                    if name is not None and not math.isnan(v):  # NaN never counts
                        values[name].append(float(v))
        if last:
            return values
        time.sleep(min(POLL, max(0.0, deadline - time.monotonic())))


def _analyse(channels: dict[str, bool], rest: dict[str, list[float]], sweep: dict[str, list[float]]):
    result: dict[str, dict] = {}
    updates: dict[str, dict[str, float]] = {}
    warnings: list[str] = []
    for name, bipolar in channels.items():
        r, s = np.asarray(rest[name]), np.asarray(sweep[name])
        counts = bool(r.size + s.size) and bool(np.all(np.mod(r, 1) == 0) and np.all(np.mod(s, 1) == 0))
        centre = _num(np.median(r), round if counts else None) if r.size else None
        lo = _num(np.percentile(s, LOW_PCT), math.floor if counts else None) if s.size else None
        hi = _num(np.percentile(s, HIGH_PCT), math.ceil if counts else None) if s.size else None
        result[name] = {"min": lo, "centre": centre, "max": hi, "samples": int(r.size + s.size)}
        if not r.size and not s.size:
            warnings.append(f"{name}: never reported (no samples at all): left as it was")
            continue
        if not s.size:
            warnings.append(f"{name}: no samples during the sweep: left as it was")
            continue
        noise = float(np.percentile(r, HIGH_PCT) - np.percentile(r, LOW_PCT)) if r.size else 0.0
        if counts:  # a device in whole counts is never known steadier than a count (a short rest may show none)
            noise = max(noise, 1.0)
        floor = max(NOISE_FACTOR * noise, 1e-9 * max(1.0, abs(lo), abs(hi)))
        if hi - lo <= floor:
            if hi - lo > 1e-9 * max(1.0, abs(lo), abs(hi)):
                warnings.append(f"{name}: never moved more in the sweep ({lo:g}..{hi:g}) than at rest "
                                f"(noise {noise:g}; was it held still at rest?): left as it was")
            else:
                warnings.append(f"{name}: never moved (swept {lo:g}..{hi:g}): left as it was")
            continue
        update = {"min": lo, "max": hi}
        if bipolar:
            if centre is None:
                warnings.append(f"{name}: bipolar but no samples at rest (no centre): left as it was")
                continue
            if not lo < centre < hi:
                warnings.append(f"{name}: rest {centre:g} is not inside the swept range {lo:g}..{hi:g}: "
                                f"left as it was")
                continue
            update["centre"] = centre
        updates[name] = update
    return result, updates, warnings


def calibration_channels(mapping) -> dict[str, bool]:
    """Every channel of a loaded mapping, and whether it is bipolar (a centre to find)."""
    return {name: ch.bipolar for name, ch in mapping._channels.items()}


class GuidedCalibration:
    """``calibrate``'s rest-then-sweep inside the live window (K): the phases run on the clock
    while the window keeps drawing, the raw values come from the session's channels each frame
    (``feed``), and ``finish`` analyses and writes them back exactly as ``calibrate`` does."""

    def __init__(self, mapping_path: str | os.PathLike, channels: MappingABC[str, bool], *,
                 rest_seconds: float = 2.0, sweep_seconds: float = 8.0, now: float | None = None) -> None:
        self.path = Path(mapping_path)
        self.channels = dict(channels)  # name -> bipolar
        start = time.monotonic() if now is None else now
        steps = [("ready", READY_SECONDS), ("rest", rest_seconds), ("get ready to sweep", READY_SECONDS),
                 ("sweep", sweep_seconds)]
        self._ends, end = [], start
        for phase, seconds in steps:
            end += seconds
            self._ends.append((phase, end))
        self.samples = {"rest": {n: [] for n in self.channels}, "sweep": {n: [] for n in self.channels}}

    def phase(self, now: float | None = None) -> tuple[str, float]:
        """(the phase, seconds left in it); ("done", 0) after the sweep."""
        now = time.monotonic() if now is None else now
        for phase, end in self._ends:
            if now < end:
                return phase, end - now
        return "done", 0.0

    def instruction(self, now: float | None = None) -> str:
        """What the performer should do now, for the cockpit."""
        phase, left = self.phase(now)
        return {"ready": f"Calibrating: let go of every control ({left:.1f} s)",
                "rest": f"Rest: hands off every control ({left:.1f} s)",
                "get ready to sweep": f"Next: move every control end to end ({left:.1f} s)",
                "sweep": f"Sweep: move every control end to end, a few times ({left:.1f} s)"}.get(phase, "")

    def feed(self, channels, now: float | None = None) -> None:
        """Take this frame's raw values (``Mapping.channels()``) into the phase under way."""
        phase, _ = self.phase(now)
        if phase in self.samples:
            for channel in channels:
                if channel.raw is not None and channel.name in self.channels:
                    self.samples[phase][channel.name].append(channel.raw)

    def finish(self) -> tuple[dict[str, dict], list[str]]:
        """Analyse and write back (``calibrate``'s rules: backup, round trip, reload check);
        returns the result per channel and the warnings."""
        result, updates, warnings = _analyse(self.channels, self.samples["rest"], self.samples["sweep"])
        if updates:
            write_calibration(self.path, updates)
        return result, warnings


def _num(x, whole: Callable[[float], int] | None = None) -> float | int:
    """A tidy number for the YAML: 6 significant digits, an int when whole; for a device that
    reads whole counts (a 10-bit ADC), a count, by ``whole`` (floor for a min, ceil for a max,
    round for a centre), since a limit between two counts means nothing to it."""
    if whole is not None:
        return int(whole(float(x)))
    v = float(f"{float(x):.6g}")
    return int(v) if v.is_integer() else v


def _report(result: dict[str, dict], warnings: list[str], out: TextIO) -> None:
    fmt = "{:<24} {:>10} {:>10} {:>10} {:>8}"
    print(fmt.format("channel", "min", "centre", "max", "samples"), file=out)
    for name, r in result.items():
        cells = ["-" if r[k] is None else f"{r[k]:g}" for k in ("min", "centre", "max")]
        print(fmt.format(name, *cells, r["samples"]), file=out)
    for w in warnings:
        print(f"warning: {w}", file=out)


# -- writing ----------------------------------------------------------------------------------

KEY_ORDER = ("range", "min", "centre", "max")


def write_calibration(path: str | os.PathLike, updates: dict[str, dict[str, float]]) -> None:
    """Set ``updates`` ({channel: {min, max[, centre]}}) under ``channels:`` in the YAML at ``path``,
    keeping comments and order; atomic, with ``<path>.bak``; checked with ``load_mapping``."""
    from ruamel.yaml import YAML
    from ruamel.yaml.comments import CommentedMap
    from ruamel.yaml.util import load_yaml_guess_indent

    path = Path(path)
    text = path.read_text(encoding="utf-8")
    _, seq_indent, seq_offset = load_yaml_guess_indent(text)
    yaml = YAML()  # round-trip
    yaml.preserve_quotes = True
    yaml.width = 4096
    yaml.indent(mapping=_mapping_indent(text), sequence=seq_indent or 2, offset=seq_offset or 0)
    data = yaml.load(text)
    if data.get("channels") is None:
        data["channels"] = CommentedMap()
    block = data["channels"]
    for name, values in updates.items():
        if block.get(name) is None:
            block[name] = CommentedMap()
        entry = block[name]
        for key in ("min", "centre", "max"):
            if key not in values:
                continue
            if key in entry:
                entry[key] = values[key]
            else:  # after the keys that come before it (range, min, centre), else first
                before = [i for i, k in enumerate(entry) if k in KEY_ORDER[:KEY_ORDER.index(key)]]
                entry.insert(before[-1] + 1 if before else 0, key, values[key])
    buffer = io.StringIO()
    yaml.dump(data, buffer)

    backup = path.with_name(path.name + ".bak")
    shutil.copy2(path, backup)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(buffer.getvalue())
            f.flush()
            os.fsync(f.fileno())
        shutil.copymode(path, tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    try:
        load_mapping(path)
    except MappingError as exc:
        shutil.copy2(backup, path)
        raise CalibrationError(f"{path}: the calibrated mapping does not load, so the original was "
                               f"restored (from {backup}):\n{exc}") from None


def _mapping_indent(text: str) -> int:
    """The file's block-mapping indent: the first indented key's column under a top-level key."""
    after_top = False
    for line in text.splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        if re.match(r"[^\s#-][^:]*:\s*(#.*)?$", line):
            after_top = True
            continue
        if after_top:
            m = re.match(r"( +)[^\s#-]", line)
            if m:
                return len(m.group(1))
        after_top = False
    return 2
