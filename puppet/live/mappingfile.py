"""Mappings: what a puppeteer's controls do to the face, written in YAML, checked before anything opens.

A mapping names the devices to open, shapes every raw channel into a clean -1..1 or 0..1 value,
and sends the shaped values to targets: FAPs (in FAPU units, as in a .fap file), muscles
(contraction 0..1), visemes and expressions (MPEG-4 FAP 1 and 2), head and eye rotations::

    # yaml-language-server: $schema=schema.json
    description: two sliders and a stick
    devices:
      box: {url: "serial:///dev/ttyACM0", options: {baudrate: 115200}}
      pad: {url: "hid://046d:c21d"}
    channels:
      box.ch0:                       # device.channel
        min: 0                       # raw values, calibrated to 0..1 (range: unipolar, the default)
        max: 1023
        dead_zone: 0.03              # 0 at the zone's edge, rising linearly to 1 at full scale
        curve: {type: expo, factor: 0.4}
        smoothing: {type: one_euro, min_cutoff: 1.0, beta: 0.5, d_cutoff: 1.0}
      pad.X:
        range: bipolar               # min / centre / max -> -1 / 0 / 1
        min: -32768
        centre: 0
        max: 32767
        invert: true
        rate_limit: 4.0              # shaped units per second
      pad.A:
        button: {mode: toggle, threshold: 0.5}
    targets:
      - {fap: open_jaw, source: box.ch0, range: [0, 600]}
      - {muscle: zygomatic_major_l, source: box.ch0, gain: 0.5}
      - {head: yaw, source: pad.X, range: [-30, 30]}          # degrees, written as FAP 49 in AU
      - {expression: joy, source: [pad.A, box.ch0], combine: max}
    idle: {blink: true, eyes: true, breath: false, seed: 7}  # idle life; default all on; false: off

Per-device ``options`` are folded into the device URL's query, so ``Mapping.devices`` is just
{name: URL}. Before its first sample a channel reads 0 (the face at rest). ``pose(t_ns)`` carries
smoothing and rate limits on to ``t_ns`` with each input held, without keeping anything: devices
that only report changes (MIDI, HID) still settle between their messages.

Loading is ``yaml.safe_load`` (nothing in a mapping is executed as code) and the whole file is
checked before a device opens; every problem is reported with the file, line, key path
(``targets[3].fap``), what was expected and, for names, the closest valid one.
``mappings/schema.json`` says the same for editors (tests keep the two in step); what a schema
cannot say (min < centre < max, monotonic points, sources naming declared channels) is checked
here.

An optional ``triggers:`` section puts poses on presses (held, latched or played once); its
checks are ``puppet.live.triggercheck``'s, run by the same checker.

The checked channels, targets and triggers become a ``Mapping`` (``puppet.live.channels``),
which shapes the channels and makes the Poses.
"""

from __future__ import annotations

import difflib
import itertools
import math
import os
import re
import reprlib
from dataclasses import dataclass
from urllib.parse import parse_qsl, urlencode, urlsplit

import yaml

from devices import DeviceError, backends, device_class
from devices.base import Url
from puppet.errors import PuppetError
from puppet.face.muscles import MUSCLE_NAMES
from puppet.fap.table import N_FAPS, faps
from puppet.live.channels import COMBINE_MODES, EXPRESSIONS, EYE_AXES, HEAD_AXES, ChannelSpec, Mapping, TargetSpec
from puppet.live.idlelife import ALL_ON, IdleSpec
from puppet.live.idlelife import PARTS as IDLE_PARTS
from puppet.live.triggercheck import check_triggers

# -- the format -------------------------------------------------------------------------------

ROOT_KEYS = ("devices", "channels", "targets", "description", "triggers", "idle")
IDLE_KEYS = IDLE_PARTS + ("seed",)
DEVICE_KEYS = ("url", "options", "description")
CHANNEL_KEYS = ("range", "min", "centre", "max", "invert", "dead_zone", "curve", "smoothing",
                "rate_limit", "button", "description")
CURVE_KEYS = {"linear": (), "expo": ("factor",), "gamma": ("gamma",), "points": ("points",)}
SMOOTHING_KEYS = {"one_euro": ("min_cutoff", "beta", "d_cutoff"), "exponential": ("tau",)}
ONE_EURO_DEFAULTS = {"min_cutoff": 1.0, "beta": 0.0, "d_cutoff": 1.0}
BUTTON_KEYS = ("mode", "threshold", "release")
BUTTON_MODES = ("toggle", "momentary")
RANGES = ("unipolar", "bipolar")
TARGET_KINDS = ("fap", "muscle", "viseme", "expression", "head", "eyes", "eye_l", "eye_r")
TARGET_KEYS = TARGET_KINDS + ("source", "combine", "range", "gain", "description")
VISEMES = range(1, 15)
DEFAULT_RANGES = {"muscle": (0.0, 1.0), "viseme": (0.0, 63.0), "expression": (0.0, 63.0)}
NEEDS_RANGE = ("fap", "head", "eyes", "eye_l", "eye_r")

DEVICE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*\Z")
SOURCE = re.compile(r"([A-Za-z_][A-Za-z0-9_-]*)\.(\S+)\Z")
URL = re.compile(r"([A-Za-z][A-Za-z0-9+.-]*):([A-Za-z][A-Za-z0-9+.-]*:)?//")  # serial:loop:// too

RAW_LIMIT = 1e12        # largest raw value a channel's min / centre / max may name
RAW_SPAN = 1e-9         # nearest min, centre and max may be (so 1 / span stays finite)
TARGET_LIMIT = 1e6      # largest target range end or gain (FAPU, degrees, contraction)
FREQUENCY_LIMIT = 1e3   # Hz: One Euro cutoffs; beta likewise in 1 / (units per second)
TAU_LIMIT = 3600.0      # seconds
RATE_LIMIT = 1e6        # shaped units per second
GAMMA_LIMIT = 100.0
ALIAS_BUDGET = 10_000   # values a document's YAML aliases may add once expanded
MAX_MAPPING_CHARS = 1 << 20  # a mapping's length (the shipped ARKit mappings are 95 KB)
"""Every number a mapping holds has a sane range (the schema says the same), so that no mapping
that loads can make a NaN or an infinity anywhere in the shaping: a cutoff of 1e308 Hz, a range
of +-1e308 or a min and max 1e-320 apart are refused with the file, line and key path. A mapping
of more than ``MAX_MAPPING_CHARS`` is refused unread (40,000 targets, 2.8 MB, held 195 MB)."""


def fap_names() -> list[str]:
    """Names a ``fap:`` target accepts (FAPs 3-68: FAP 1 and 2 are the viseme / expression targets)."""
    return [f.name for f in faps() if f.number > 2]


# -- errors -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Problem:
    """One thing wrong in a mapping: where (key path, line) and what."""

    path: str
    line: int | None
    message: str


class MappingError(PuppetError, ValueError):
    """A mapping that cannot be used; ``problems`` lists everything wrong, each on its own line."""

    def __init__(self, file: str, problems: list[Problem]) -> None:
        self.file, self.problems = file, list(problems)
        super().__init__(str(self))

    def __str__(self) -> str:
        lines = []
        for p in self.problems:
            where = f"{self.file}:{p.line}" if p.line else self.file
            lines.append(f"{where}: {p.path}: {p.message}" if p.path else f"{where}: {p.message}")
        return "\n".join(lines)


# -- loading ----------------------------------------------------------------------------------

def load_mapping(path: str | os.PathLike) -> Mapping:
    """Read, check and compile a mapping file; ``MappingError`` lists every problem."""
    file = str(path)
    try:
        with open(path, encoding="utf-8") as stream:
            text = stream.read(MAX_MAPPING_CHARS + 1)
    except (OSError, UnicodeDecodeError) as exc:
        raise MappingError(file, [Problem("", None, f"cannot read the mapping: {exc}")]) from None
    return parse_mapping(text, file)


def _misindented(text: str, line: int) -> int | None:
    """The line whose indentation went wrong when PyYAML stops at ``line`` (0-based): the line
    before it, when that one is indented less, opens no block (``key: value`` or a flow value), so
    ``line`` cannot belong under it, and the line before that is indented as ``line`` is (the keys
    it belongs with). PyYAML only notices at the deeper line ("expected <block end>", or "mapping
    values are not allowed" after a plain value, which it reads as going on)."""
    lines = text.splitlines()
    if not 0 < line < len(lines):
        return None
    previous, before = itertools.islice(_content_lines_before(lines, line), 2)
    if previous is None or before is None:
        return None
    body = lines[previous].split(" #", 1)[0].rstrip()
    deeper = _indent(lines[line]) > _indent(lines[previous])
    among = _indent(lines[before]) == _indent(lines[line])
    return previous if deeper and among and not body.endswith(":") and not body.lstrip().startswith("- ") else None


def _content_lines_before(lines: list[str], line: int):
    """The line numbers before ``line`` that hold more than a comment, nearest first (then Nones)."""
    for k in range(line - 1, -1, -1):
        if lines[k].strip() and not lines[k].lstrip().startswith("#"):
            yield k
    yield from itertools.repeat(None, 2)


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


def _indent_problem(text: str, culprit: int, stopped: int) -> str:
    lines = text.splitlines()
    return (f"YAML indentation: line {culprit + 1} is indented {_indent(lines[culprit])} spaces and opens no "
            f"block, so line {stopped + 1}, indented {_indent(lines[stopped])}, fits nowhere; line "
            f"{culprit + 1} is most likely indented wrong (give it the indentation of the keys it belongs with)")


def _between(text: str, exc: yaml.YAMLError, stopped: int) -> str | None:
    """Where PyYAML stops at a line indented less than the line before it but more than the keys
    of the block around them (its ``context_mark``): that line fits neither, and is named."""
    block, lines = getattr(exc, "context_mark", None), text.splitlines()
    previous = next(itertools.islice(_content_lines_before(lines, stopped), 1), None) if stopped < len(lines) else None
    if block is None or previous is None or block.line >= stopped:
        return None
    indent, above = _indent(lines[stopped]), _indent(lines[previous])
    if not block.column < indent < above:
        return None
    return (f"YAML indentation: line {stopped + 1} is indented {indent} space{'s' * (indent != 1)}, less than "
            f"line {previous + 1} ({above}) and more than the keys from line {block.line + 1} ({block.column}), so it fits in neither; "
            f"give it the indentation of the keys it belongs with")


def parse_mapping(text: str, file: str = "<mapping>") -> Mapping:
    """A mapping from YAML text (``file`` names it in errors)."""
    if len(text) > MAX_MAPPING_CHARS:
        raise MappingError(file, [Problem("", None, f"expected a mapping of at most {MAX_MAPPING_CHARS >> 20} MiB "
                                                    f"(the shipped ARKit mappings are 95 KB), found more")])
    try:
        lines, duplicates, added, data = _load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        what = " ".join(filter(None, (getattr(exc, "context", None), getattr(exc, "problem", None)))) or str(exc)
        kind = "YAML syntax error"
        if isinstance(exc, yaml.constructor.ConstructorError):  # a !!python/... tag, say
            kind, what = "unsupported YAML", f"{what}; expected plain data (mappings, lists, strings, numbers)"
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        noticed = "expected" in what or "mapping values are not allowed" in what
        culprit = _misindented(text, mark.line) if mark is not None and noticed else None
        if culprit is not None:
            raise MappingError(file, [Problem("", culprit + 1, _indent_problem(text, culprit, mark.line))]) from None
        between = _between(text, exc, mark.line) if mark is not None and "block mapping" in what else None
        if between is not None:
            raise MappingError(file, [Problem("", mark.line + 1, between)]) from None
        raise MappingError(file, [Problem("", mark.line + 1 if mark else None, f"{kind}{at}: {what}")]) from None
    except RecursionError:
        raise MappingError(file, [Problem("", None, "the YAML is nested too deeply")]) from None
    except UnicodeError as exc:  # text that is no valid Unicode (lone surrogates)
        raise MappingError(file, [Problem("", None, f"expected UTF-8 text, found {_clip(str(exc), 80)}")]) from None
    except ValueError as exc:  # a number PyYAML cannot build (an integer of over 4300 digits)
        raise MappingError(file, [Problem("", None, f"expected numbers of sane size, found one that is "
                                                    f"not ({_clip(str(exc), 60)})")]) from None
    if added > ALIAS_BUDGET:
        raise MappingError(file, [Problem("", None, f"expected YAML aliases to add at most {ALIAS_BUDGET:,} "
                                                    f"values when expanded, found more (aliases nested in aliases)")])
    return compile_mapping(data, file, lines=lines, duplicates=duplicates)


_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
"""libyaml's safe loader where PyYAML was built with it (its wheels are): the same documents and
marks, read about 10 times faster than the pure-Python one (0.1 s for a shipped ARKit mapping)."""


def _load(text: str) -> tuple[dict[tuple, int], list[Problem], int, object]:
    """The document composed once: its lines, duplicate keys and alias growth (``_lines``), then,
    only when the aliases are within ``ALIAS_BUDGET``, the data built from it (else None)."""
    loader = _LOADER(text)
    try:
        root = loader.get_single_node()
        lines, duplicates, added = _lines(root)
        data = loader.construct_document(root) if root is not None and added <= ALIAS_BUDGET else None
        return lines, duplicates, added, data
    finally:
        loader.dispose()


def _lines(root) -> tuple[dict[tuple, int], list[Problem], int]:
    """Line of every key path (from the composed YAML nodes), the keys written twice, and how
    many values the document's aliases add when expanded (counted, never expanded)."""
    lines: dict[tuple, int] = {}
    duplicates: list[Problem] = []
    seen: set[int] = set()
    sizes: dict[int, int] = {}
    budget = ALIAS_BUDGET + 1

    def expanded(node) -> int:
        if id(node) not in sizes:
            sizes[id(node)] = 0  # a node inside itself (a recursive alias) counts once
            sizes[id(node)] = min(1 + sum(expanded(c) for c in _children(node)), budget)
        return sizes[id(node)]

    def walk(node, path: tuple, line: int) -> None:
        lines.setdefault(path, line)
        if id(node) in seen:  # an alias: walked once (no blow-up on nested aliases)
            return
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            first: dict[str, int] = {}
            for key, value in node.value:
                name = key.value if isinstance(key, yaml.ScalarNode) else None
                key_line = key.start_mark.line + 1
                if name is not None and name != "<<" and name in first:
                    duplicates.append(Problem(_format_path(path + (name,)), key_line,
                                              f"duplicate key {name!r} (first on line {first[name]}): "
                                              f"expected each key once"))
                elif name is not None:
                    first[name] = key_line
                walk(value, path + (name,), key_line)
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                walk(item, path + (i,), item.start_mark.line + 1)

    if root is None:
        return lines, duplicates, 0
    distinct, references = _distinct_nodes(root)
    budget += distinct
    added = expanded(root) - distinct if references + 1 > distinct else 0  # else a tree: no alias
    if added <= ALIAS_BUDGET:
        walk(root, (), root.start_mark.line + 1)
    return lines, duplicates, added


def _distinct_nodes(root) -> tuple[int, int]:
    """How many nodes a composed YAML document holds, each alias's target once, and how many
    times nodes are named as children (one less than the nodes when no alias repeats one)."""
    seen, stack, references = {id(root)}, [root], 0
    while stack:
        for child in _children(stack.pop()):
            references += 1
            if id(child) not in seen:
                seen.add(id(child))
                stack.append(child)
    return len(seen), references


def _children(node) -> list:
    """A composed YAML node's keys and values, or items; none for a scalar."""
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return node.value if isinstance(node, yaml.SequenceNode) else []


def _format_path(path: tuple) -> str:
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        elif isinstance(part, str) and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", part):
            out += f".{part}" if out else part
        else:
            out += f'["{part}"]'
    return out


_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxlist, _SHORT.maxdict, _SHORT.maxstring, _SHORT.maxother = 2, 6, 4, 60, 60
_SHORT.maxlong = 40


def _clip(text: str, n: int) -> str:
    return text if len(text) <= n else text[:n - 3] + "..."


def _got(value) -> str:
    """What was found, in a few words: never longer than a line, whatever the value's size."""
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return f"{str(value).lower()} (a boolean)"
    if isinstance(value, dict):
        return "a mapping" if value else "an empty mapping"
    if isinstance(value, int) and value.bit_length() > 128:
        return f"an integer of about {int(value.bit_length() * 0.30103) + 1} digits"
    text = _SHORT.repr(value)
    if isinstance(value, list):
        return text if len(text) <= 40 else f"a list of {len(value)} items"
    return _clip(text, 60)


def _finite(value) -> bool:
    """A number (not a boolean) that is finite as a float: 1e400 written as an integer is not."""
    if not _is_number(value):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _closest(word, choices) -> str:
    if not isinstance(word, str):
        return ""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.5)
    if not close:
        close = difflib.get_close_matches(word.lower(), [c.lower() for c in choices], n=1, cutoff=0.5)
        close = [c for c in choices if c.lower() in close]
    return f"; did you mean {close[0]!r}?" if close else ""


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


# -- checking ---------------------------------------------------------------------------------

class _Checker:
    """Walks the loaded document once, collecting every problem with its path and line."""

    def __init__(self, data, lines: dict[tuple, int] | None) -> None:
        self.lines = lines or {}
        self.problems: list[Problem] = []
        # the declared names, even where their own entries have problems (so that a bad channel
        # is reported once, not again at every source that names it)
        top = data if isinstance(data, dict) else {}
        self.declared_devices = top.get("devices") if isinstance(top.get("devices"), dict) else {}
        self.declared_channels = top.get("channels") if isinstance(top.get("channels"), dict) else {}

    def error(self, path: tuple, message: str) -> None:
        line, p = None, path
        while line is None:
            line = self.lines.get(p)
            if not p:
                break
            p = p[:-1]
        self.problems.append(Problem(_format_path(path), line, message))

    def expect(self, path: tuple, expected: str, value, hint: str = "") -> None:
        self.error(path, f"expected {expected}, got {_got(value)}{hint}")

    # -- small pieces ------------------------------------------------------------------------

    def mapping(self, path: tuple, value, allowed, what: str, required=()) -> dict | None:
        """``value`` as a dict with string keys among ``allowed``; None if it is no mapping."""
        if not isinstance(value, dict):
            self.expect(path, f"a mapping ({what})", value)
            return None
        for key in value:
            if not isinstance(key, str):
                self.expect(path + (key,), f"a key among {', '.join(allowed)}", key)
            elif key not in allowed:
                self.error(path + (key,), f"unknown key {key!r} in {what}: expected one of "
                                          f"{', '.join(allowed)}{_closest(key, allowed)}")
        for key in required:
            if key not in value:
                self.error(path, f"missing key {key!r}: {what} needs {', '.join(required)}")
        return value

    def number(self, path: tuple, value, low=None, high=None, low_open=False, high_open=False,
               expected: str | None = None) -> float | None:
        ok = _finite(value)
        if ok and low is not None:
            ok = value > low if low_open else value >= low
        if ok and high is not None:
            ok = value < high if high_open else value <= high
        if not ok:
            if expected is None:
                expected = "a number"
                if low is not None and high is not None:
                    expected += f" from {low:g} to {high:g}" + (" (exclusive)" if low_open or high_open else "")
                elif low is not None:
                    expected = f"a number {'>' if low_open else '>='} {low:g}"
            self.expect(path, expected, value)
            return None
        return float(value)

    def raw_number(self, path: tuple, value) -> float | None:
        """A raw device value (a channel's min, centre or max)."""
        return self.number(path, value, -RAW_LIMIT, RAW_LIMIT,
                           expected=f"a raw value from {-RAW_LIMIT:g} to {RAW_LIMIT:g}")

    def choice(self, path: tuple, value, choices, what: str):
        if isinstance(value, str) and value in choices:
            return value
        self.expect(path, f"{what}: one of {', '.join(map(str, choices))}", value, _closest(value, choices))
        return None

    def string(self, path: tuple, value) -> str | None:
        if isinstance(value, str):
            return value
        self.expect(path, "a string", value)
        return None

    # -- the document ------------------------------------------------------------------------

    def root(self, data) -> tuple[dict, dict, list, IdleSpec | None] | None:
        if not isinstance(data, dict):
            self.expect((), "a mapping with the keys devices, channels and targets at the top of the file", data)
            return None
        self.mapping((), data, ROOT_KEYS, "a mapping file", required=("devices", "channels", "targets"))
        if "description" in data:
            self.string(("description",), data["description"])
        devices = self.devices(data["devices"]) if "devices" in data else {}
        channels = self.channels(data["channels"]) if "channels" in data else {}
        targets = self.targets(data["targets"], channels) if "targets" in data else []
        idle = self.idle(data["idle"]) if "idle" in data else ALL_ON
        return devices, channels, targets, idle

    def idle(self, value) -> IdleSpec | None:
        """``idle: false`` (none), ``true`` (all parts), or ``{blink, eyes, breath: bool, seed: int}``."""
        if isinstance(value, bool):
            return ALL_ON if value else None
        if not isinstance(value, dict):
            self.expect(("idle",), "true, false or a mapping (blink, eyes, breath: true/false; seed: a whole "
                                   "number)", value)
            return None
        self.mapping(("idle",), value, IDLE_KEYS, "idle life")
        parts = {}
        for part in IDLE_PARTS:
            on = value.get(part, True)
            if not isinstance(on, bool):
                self.expect(("idle", part), "true or false", on)
            parts[part] = on is not False
        seed = value.get("seed")
        if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2 ** 63):
            self.expect(("idle", "seed"), f"a whole number from 0 to {2 ** 63 - 1}", seed)
            seed = None
        return IdleSpec(**parts, seed=seed)

    def devices(self, value) -> dict[str, str]:
        path = ("devices",)
        if not isinstance(value, dict) or not value:
            self.expect(path, "a mapping of device name -> {url: ...} with at least one device", value)
            return {}
        out = {}
        for name, spec in value.items():
            where = path + (name,)
            if not isinstance(name, str) or not DEVICE_NAME.match(name):
                self.expect(where, "a device name of letters, digits, '_' and '-' (no dots)", name)
                continue
            spec = self.mapping(where, spec, DEVICE_KEYS, f"device {name!r}", required=("url",))
            if spec is None:
                continue
            if "description" in spec:
                self.string(where + ("description",), spec["description"])
            url = spec.get("url")
            m = URL.match(url) if isinstance(url, str) else None
            if "url" in spec and m is None:
                self.expect(where + ("url",), "a device URL scheme://..., e.g. 'serial:///dev/ttyACM0' "
                                              "or 'serial:loop://'", url)
                url = None
            elif m is not None and m.group(1) not in backends():
                self.error(where + ("url",), f"unknown device URL scheme {m.group(1)!r}: expected one of "
                                             f"{', '.join(sorted(backends()))}{_closest(m.group(1), backends())}")
                url = None
            options = spec.get("options", {})
            if not isinstance(options, dict):
                self.expect(where + ("options",), "a mapping of option -> string, number or boolean", options)
                options = {}
            good = {}
            for key, option in options.items():
                if not isinstance(key, str) or not (isinstance(option, str) or _finite(option)
                                                    or isinstance(option, bool)):
                    self.expect(where + ("options", key), "an option name with a string, number or boolean", option)
                else:
                    good[key] = option
            if url is not None:
                out[name] = self.url_with_options(where, url, good)
                self.device_options(where, out[name], good)
        return out

    def device_options(self, where: tuple, url: str, options: dict) -> None:
        """Every option of the device URL (its query and ``options``) is one its backend reads."""
        try:
            parsed = Url.parse(url)
            backend = device_class(parsed.scheme, url)
        except DeviceError:  # a missing optional library is said when the device opens
            return
        for key in parsed.options:
            problem = backend.unknown_option(parsed, key)
            if problem:
                self.error(where + (("options", key) if key in options else ("url",)), problem)

    def url_with_options(self, where: tuple, url: str, options: dict) -> str:
        """The URL with ``options`` folded into its query (an option given twice is an error)."""
        if not options:
            return url
        parts = urlsplit(url)
        query = dict(parse_qsl(parts.query))
        extra = []
        for key, value in options.items():
            if key in query:
                self.error(where + ("options", key), f"option {key!r} is also in the url: expected it once")
                continue
            extra.append((key, str(value).lower() if isinstance(value, bool) else str(value)))
        if not extra:
            return url
        base, _, fragment = url.partition("#")
        return base + ("&" if parts.query else "?") + urlencode(extra) + ("#" + fragment if fragment else "")

    def channels(self, value) -> dict[str, ChannelSpec]:
        path = ("channels",)
        if not isinstance(value, dict):
            self.expect(path, "a mapping of device.channel -> channel options", value)
            return {}
        out = {}
        for name, spec in value.items():
            where = path + (name,)
            m = SOURCE.match(name) if isinstance(name, str) else None
            if m is None:
                self.expect(where, "a channel named device.channel (e.g. box.ch0)", name)
                continue
            if m.group(1) not in self.declared_devices:
                self.error(where, f"device {m.group(1)!r} is not defined: expected one of the devices "
                                  f"({', '.join(map(str, self.declared_devices))})"
                                  f"{_closest(m.group(1), self.declared_devices)}")
            elif problem := self.channel_problem(m.group(1), m.group(2)):
                self.error(where, problem)
            parsed = self.channel(where, name, m.group(1), m.group(2), {} if spec is None else spec)
            if parsed is not None:
                out[name] = parsed
        return out

    def channel_problem(self, device: str, channel: str) -> str | None:
        """Why the declared ``device`` has no ``channel`` (``Device.unknown_channel``: a keys://
        device's channels are keys); None when it may have it, or its URL is wrong (said there)."""
        spec = self.declared_devices.get(device)
        url = spec.get("url") if isinstance(spec, dict) else None
        try:
            parsed = Url.parse(url) if isinstance(url, str) else None
            backend = device_class(parsed.scheme, url) if parsed is not None else None
        except DeviceError:
            return None
        return None if backend is None else backend.unknown_channel(parsed, channel)

    def channel(self, where: tuple, name: str, device: str, channel: str, spec) -> ChannelSpec | None:
        spec = self.mapping(where, spec, CHANNEL_KEYS, f"channel {name!r}")
        if spec is None:
            return None
        before = len(self.problems)
        polarity = spec.get("range", "unipolar")
        if "range" in spec:
            polarity = self.choice(where + ("range",), polarity, RANGES, "a channel range")
        bipolar = polarity == "bipolar"
        low = self.raw_number(where + ("min",), spec["min"]) if "min" in spec else (-1.0 if bipolar else 0.0)
        high = self.raw_number(where + ("max",), spec["max"]) if "max" in spec else 1.0
        centre = None
        if "centre" in spec:
            centre = self.raw_number(where + ("centre",), spec["centre"])
            if polarity == "unipolar":
                self.error(where + ("centre",), "centre applies to a bipolar channel: expected range: bipolar "
                                                "with centre, or no centre")
        if low is not None and high is not None:
            if not low < high:
                self.error(where + ("max",), f"expected max greater than min ({low:g}), got {high:g} "
                                             f"(use invert: true for a reversed control)")
            elif high - low < RAW_SPAN:
                self.error(where + ("max",), f"expected max at least {RAW_SPAN:g} above min ({low:g}), got {high:g}")
            elif centre is not None and bipolar and not low < centre < high:
                self.error(where + ("centre",), f"expected centre between min ({low:g}) and max ({high:g}), "
                                                f"got {centre:g}")
            elif centre is not None and bipolar and min(centre - low, high - centre) < RAW_SPAN:
                self.error(where + ("centre",), f"expected centre at least {RAW_SPAN:g} from min ({low:g}) "
                                                f"and max ({high:g}), got {centre:g}")
        invert = spec.get("invert", False)
        if not isinstance(invert, bool):
            self.expect(where + ("invert",), "true or false", invert)
        dead = 0.0
        if "dead_zone" in spec:
            dead = self.number(where + ("dead_zone",), spec["dead_zone"], 0.0, 1.0, high_open=True,
                               expected="a number from 0 to 1 (excluding 1): the fraction of the "
                                        "calibrated range that reads 0")
        curve = self.curve(where + ("curve",), spec["curve"], bipolar) if "curve" in spec else None
        smoothing = self.smoothing(where + ("smoothing",), spec["smoothing"]) if "smoothing" in spec else None
        rate = None
        if "rate_limit" in spec:
            rate = self.number(where + ("rate_limit",), spec["rate_limit"], 0.0, RATE_LIMIT, low_open=True,
                               expected=f"a number > 0 and <= {RATE_LIMIT:g} (units per second)")
        button = self.button(where + ("button",), spec["button"]) if "button" in spec else None
        if "button" in spec:
            for key in ("dead_zone", "curve"):
                if key in spec:
                    self.error(where + (key,), f"a button channel is 0 or 1: expected no {key} with button")
        if "description" in spec:
            self.string(where + ("description",), spec["description"])
        if len(self.problems) > before:
            return None
        if centre is None:
            centre = (low + high) / 2
        return ChannelSpec(name, device, channel, bipolar, low, centre, high, invert, dead, curve,
                            smoothing, rate, button)

    def curve(self, where: tuple, value, bipolar: bool) -> tuple | None:
        kind = value.get("type") if isinstance(value, dict) else None
        if not isinstance(value, dict):
            self.expect(where, f"a mapping with a type ({', '.join(CURVE_KEYS)})", value)
            return None
        if "type" not in value:
            self.error(where, f"missing key 'type': expected a curve type, one of {', '.join(CURVE_KEYS)}")
            return None
        if self.choice(where + ("type",), kind, CURVE_KEYS, "a curve type") is None:
            return None
        keys = ("type",) + CURVE_KEYS[kind]
        if self.mapping(where, value, keys, f"a {kind} curve", required=keys) is None:
            return None
        if kind == "linear":
            return None
        if kind == "expo":
            k = self.number(where + ("factor",), value.get("factor"), 0.0, 1.0,
                            expected="a number from 0 (linear) to 1 (cubic)") if "factor" in value else None
            return None if k is None else ("expo", k)
        if kind == "gamma":
            g = self.number(where + ("gamma",), value.get("gamma"), 0.0, GAMMA_LIMIT, low_open=True,
                            expected=f"a number > 0 and <= {GAMMA_LIMIT:g}") if "gamma" in value else None
            return None if g is None else ("gamma", g)
        return self.points(where + ("points",), value.get("points"), bipolar) if "points" in value else None

    def points(self, where: tuple, value, bipolar: bool) -> tuple | None:
        expected = "a list of at least two [x, y] pairs, each number from 0 to 1"
        if not isinstance(value, list) or len(value) < 2:
            self.expect(where, expected, value)
            return None
        xs, ys = [], []
        for i, pair in enumerate(value):
            if not (isinstance(pair, list) and len(pair) == 2
                    and all(_finite(v) and 0 <= v <= 1 for v in pair)):
                self.expect(where + (i,), "an [x, y] pair of numbers from 0 to 1", pair)
                return None
            xs.append(float(pair[0]))
            ys.append(float(pair[1]))
        if xs[0] != 0.0 or xs[-1] != 1.0:
            self.error(where, f"expected the points to run from x = 0 to x = 1, got x from {xs[0]:g} to {xs[-1]:g}")
            return None
        for i in range(1, len(xs)):
            if not xs[i] > xs[i - 1]:
                self.error(where + (i,), f"expected x strictly rising (a monotonic curve), got x = {xs[i]:g} "
                                         f"after x = {xs[i - 1]:g}")
                return None
            if ys[i] < ys[i - 1]:
                self.error(where + (i,), f"expected y never falling (a monotonic curve), got y = {ys[i]:g} "
                                         f"after y = {ys[i - 1]:g}")
                return None
        if bipolar and ys[0] != 0.0:
            self.error(where + (0,), f"expected [0, 0] first on a bipolar channel (the curve acts on the "
                                     f"magnitude, so the centre must stay 0), got [0, {ys[0]:g}]")
            return None
        return ("points", tuple(xs), tuple(ys))

    def smoothing(self, where: tuple, value) -> tuple | None:
        if not isinstance(value, dict):
            self.expect(where, f"a mapping with a type ({', '.join(SMOOTHING_KEYS)})", value)
            return None
        if "type" not in value:
            self.error(where, f"missing key 'type': expected a smoothing type, one of {', '.join(SMOOTHING_KEYS)}")
            return None
        kind = self.choice(where + ("type",), value["type"], SMOOTHING_KEYS, "a smoothing type")
        if kind is None:
            return None
        keys = ("type",) + SMOOTHING_KEYS[kind]
        required = ("type", "tau") if kind == "exponential" else ("type",)
        if self.mapping(where, value, keys, f"{kind} smoothing", required=required) is None:
            return None
        if kind == "exponential":
            tau = self.number(where + ("tau",), value["tau"], 0.0, TAU_LIMIT, low_open=True,
                              expected=f"a time constant in seconds > 0 and <= {TAU_LIMIT:g}") if "tau" in value else None
            return None if tau is None else ("exponential", tau)
        params = []
        for key in SMOOTHING_KEYS["one_euro"]:
            v = value.get(key, ONE_EURO_DEFAULTS[key])
            params.append(self.number(where + (key,), v, 0.0, FREQUENCY_LIMIT, low_open=key != "beta",
                                      expected=f"a number >= 0 and <= {FREQUENCY_LIMIT:g}" if key == "beta"
                                      else f"a frequency in Hz > 0 and <= {FREQUENCY_LIMIT:g}"))
        return None if None in params else ("one_euro", *params)

    def button(self, where: tuple, value) -> tuple | None:
        spec = self.mapping(where, value, BUTTON_KEYS, "a button", required=("mode",))
        if spec is None or "mode" not in spec:
            return None
        mode = self.choice(where + ("mode",), spec["mode"], BUTTON_MODES, "a button mode")
        threshold = self.number(where + ("threshold",), spec.get("threshold", 0.5), -1.0, 1.0,
                                expected="a number from -1 to 1 (a shaped value)")
        release = self.number(where + ("release",), spec["release"], -1.0, 1.0,
                              expected="a number from -1 to 1 (a shaped value)") if "release" in spec else threshold
        if threshold is not None and release is not None and release > threshold:
            self.error(where + ("release",), f"expected release <= threshold ({threshold:g}), got {release:g}")
            return None
        if None in (mode, threshold, release):
            return None
        return (mode, threshold, release)

    def targets(self, value, channels: dict) -> list[TargetSpec]:
        path = ("targets",)
        if not isinstance(value, list) or not value:
            self.expect(path, "a list of targets (at least one)", value)
            return []
        out = []
        for i, spec in enumerate(value):
            target = self.target(path + (i,), spec, channels)
            if target is not None:
                out.append(target)
        return out

    def target(self, where: tuple, spec, channels: dict) -> TargetSpec | None:
        spec = self.mapping(where, spec, TARGET_KEYS, "a target")
        if spec is None:
            return None
        before = len(self.problems)
        kinds = [k for k in TARGET_KINDS if k in spec]
        if len(kinds) != 1:
            got = f"{' and '.join(kinds)}" if kinds else "none"
            self.error(where, f"expected exactly one of {', '.join(TARGET_KINDS)} in a target, got {got}")
            kind, key = None, None
        else:
            kind = kinds[0]
            key = self.target_key(where + (kind,), kind, spec[kind])
        sources = self.sources(where + ("source",), spec.get("source"), channels) if "source" in spec else None
        if "source" not in spec:
            self.error(where, "missing key 'source': expected a source device.channel or a list of them")
        combine = self.choice(where + ("combine",), spec["combine"], COMBINE_MODES, "a combine mode") \
            if "combine" in spec else "sum"
        gain = self.number(where + ("gain",), spec["gain"], -TARGET_LIMIT, TARGET_LIMIT) if "gain" in spec else 1.0
        rng = None
        if "range" in spec:
            r = spec["range"]
            if isinstance(r, list) and len(r) == 2 and all(_finite(v) and abs(v) <= TARGET_LIMIT for v in r):
                rng = (float(r[0]), float(r[1]))
            else:
                unit = " in degrees" if kind in NEEDS_RANGE[1:] else " in FAPU units" if kind == "fap" else ""
                self.expect(where + ("range",), f"two numbers [low, high]{unit}, each from {-TARGET_LIMIT:g} "
                                                f"to {TARGET_LIMIT:g}", r)
        elif kind in NEEDS_RANGE:
            unit = "degrees" if kind != "fap" else "FAPU units"
            self.error(where, f"missing key 'range': expected range: [low, high] in {unit} for a {kind}: target")
        if "description" in spec:
            self.string(where + ("description",), spec["description"])
        if sources:
            polarities = {channels[s].bipolar for s in sources}
            if len(polarities) > 1:
                self.error(where + ("source",), "expected sources that are all bipolar or all unipolar, got "
                           + ", ".join(f"{s} ({'bipolar' if channels[s].bipolar else 'unipolar'})" for s in sources))
        if len(self.problems) > before or kind is None or key is None or not sources:
            return None
        return TargetSpec(kind, key, sources, combine, rng or DEFAULT_RANGES.get(kind), gain)

    def target_key(self, where: tuple, kind: str, value):
        if isinstance(value, float) and value.is_integer():  # 3.0 is the number 3, as in JSON
            value = int(value)
        if kind == "fap":
            names = fap_names()
            if isinstance(value, int) and not isinstance(value, bool):
                if 3 <= value <= N_FAPS:
                    return value
                if value in (1, 2):
                    self.error(where, f"FAP {value} is not a value: expected a FAP 3-68, and a "
                                      f"{'viseme' if value == 1 else 'expression'}: target for FAP {value}")
                    return None
            elif isinstance(value, str):
                if value in names:
                    return names.index(value) + 3
                if value in ("viseme", "expression"):
                    self.error(where, f"FAP {value!r} is not a value: expected a FAP 3-68, and a {value}: target")
                    return None
            self.expect(where, "a FAP name or number 3-68", value, _closest(value, names))
            return None
        if kind == "muscle":
            if value in MUSCLE_NAMES:
                return value
            self.expect(where, "a muscle of the default face (puppet.face.muscles.MUSCLE_NAMES)", value,
                        _closest(value, MUSCLE_NAMES))
            return None
        if kind == "viseme":
            if isinstance(value, int) and not isinstance(value, bool) and value in VISEMES:
                return value
            self.expect(where, "a viseme number 1-14", value)
            return None
        if kind == "expression":
            if isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 6:
                return value
            if isinstance(value, str) and value in EXPRESSIONS:
                return EXPRESSIONS[value]
            self.expect(where, f"an expression number 1-6 or name ({', '.join(EXPRESSIONS)})", value,
                        _closest(value, EXPRESSIONS))
            return None
        axes = HEAD_AXES if kind == "head" else EYE_AXES[kind]
        return self.choice(where, value, axes, f"a {kind} axis")

    def sources(self, where: tuple, value, channels: dict) -> list[str] | None:
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list) or not items:
            self.expect(where, "a source device.channel or a list of them", value)
            return None
        out = []
        for i, source in enumerate(items):
            at = where if isinstance(value, str) else where + (i,)
            m = SOURCE.match(source) if isinstance(source, str) else None
            if m is None:
                self.expect(at, "a source named device.channel (e.g. box.ch0)", source)
            elif m.group(1) not in self.declared_devices:
                self.error(at, f"source {source!r} names device {m.group(1)!r}, which is not defined: expected "
                               f"one of the devices ({', '.join(map(str, self.declared_devices))})"
                               f"{_closest(m.group(1), self.declared_devices)}")
            elif source not in channels:
                if source not in self.declared_channels:
                    self.error(at, f"source {source!r} is not a channel of the mapping: expected one of "
                                   f"the channels{_closest(source, self.declared_channels)} (add it under channels)")
            else:
                out.append(source)
        return out if len(out) == len(items) else None


def compile_mapping(data, file: str = "<mapping>", *, lines: dict | None = None, duplicates=()) -> Mapping:
    """Check an already-loaded document (a dict as ``yaml.safe_load`` gives) and compile it into a
    ``Mapping``; ``MappingError`` lists every problem (``lines``: each key path's line)."""
    checker = _Checker(data, lines)
    checker.problems.extend(duplicates)
    result = checker.root(data)
    triggers = []
    if result is not None and "triggers" in data:
        triggers = check_triggers(checker, data["triggers"], result[1], file)
    if checker.problems:
        checker.problems.sort(key=lambda p: (p.line or 0))
        raise MappingError(file, checker.problems)
    devices, channels, targets, idle = result
    return Mapping(file, devices, channels, targets, data.get("description", ""), triggers, idle)


