"""HID report descriptors: which input values a report carries, where, and what they are called.

A HID device describes its reports in a *report descriptor* (HID 1.11, section 6.2.2): a string of
short items, each a prefix byte (``tag << 4 | type << 2 | size``, size code 0, 1, 2 or 4 bytes)
and its little-endian data. ``parse_descriptor`` walks it and returns one ``ReportField`` per
``Input`` main item that carries data; ``ReportLayout`` compiles those into channels and pulls the
values out of a raw report.

What is read:
- Main items: Input (Constant inputs are padding: they advance the bit offset and make no channel;
  Output and Feature items are skipped but do not advance input offsets), Collection, End Collection.
- Global items: Usage Page, Logical Minimum/Maximum (signed, as the spec says; a Logical Maximum
  that comes out negative above a non-negative minimum is read as unsigned, the common encoding
  slip Linux forgives too), Report Size, Report Count, Report ID, Push, Pop. Physical extents,
  units and unit exponents are read past.
- Local items: Usage, Usage Minimum/Maximum (a 4-byte usage carries its own page in the high 16
  bits; a shorter one takes the Usage Page in force at its main item, as Linux pages them: a
  Usage Page item between the usages and their Input re-pages them). A Minimum/Maximum range
  runs over the values as written and is paged by the Maximum's size, as Linux does (a 1-byte
  Minimum 0 with a 4-byte Maximum 0x0000FFFF gives page 0 usages; hid-tools gives none); a
  Maximum with no Minimum starts from 0. Designators, strings and delimiters are read past.
- Long items (prefix 0xFE) are skipped whole.
- Unknown main items and items of the reserved type are skipped with a warning, as the Linux
  kernel does: some real pads' descriptors end in a stray 0x00 byte (Xbox One S on its Linux
  firmware, Xbox Elite 2, 8BitDo SN30 Pro).

Bounds (the kernel's, hid-core.c), so that no descriptor can make the parser allocate or work
without limit: a descriptor at most ``MAX_DESCRIPTOR_BYTES`` (4,096), Push nested at most
``MAX_PUSH`` (4) deep, Report Size at most 256 bits, Report Count and the usages of one main item
at most ``MAX_USAGES`` (12,288), and a report at most ``MAX_REPORT_BYTES`` (16,384). The kernel lets a
descriptor repeat those in many reports and fields; we also bound the whole descriptor's input
values (``MAX_INPUT_VALUES``, 16,384, each a channel) and the usages its input fields keep
(``MAX_KEPT_USAGES``, 49,152; a variable field keeps one per value), about three times the most of
135 real descriptors, so a few hundred bytes cannot ask for millions of channels. Past a bound the
descriptor is refused with the byte offset, but for a Usage Minimum/Maximum range, which is cut
to the bound with a warning (vendor pages often declare 0-0xFFFF). Inputs outside any numbered
report in a descriptor that numbers its reports are kept as report 0 with a warning: no such
report ever arrives, and ``ReportLayout`` makes no channel of them.

Not supported (documented so nobody relies on it):
- Array inputs (the Array flag clear: keyboard key arrays, some button arrays) are not expanded
  into one channel per usage; each array slot becomes one raw channel (``array<N>``, the selector
  value itself, not scaled).
- Fields wider than 32 bits are skipped (no channel); HID values are at most 32 bits in practice.
- Relative inputs (mice) are reported like absolute ones: the value of each report, not a sum.
- Physical ranges and units are not applied: values are scaled from the logical range.

Scaling (``ReportLayout``, unless ``raw=True``):
- buttons (Button page, and any 1-bit field): 0.0 or 1.0;
- hat switches: the direction in degrees, ``(v - min) * 360 / (max - min + 1)`` (8 positions give
  0, 45, ..., 315), and -1.0 when the value is outside the logical range (the null state: centred);
- other values with a negative logical minimum (signed): ``v / max`` for v >= 0 and ``v / -min``
  below, so 0 stays exactly 0 and the ends are -1 and +1;
- other values with a non-negative minimum: ``(v - min) / (max - min)``, 0..1;
- values outside the logical range are clamped to it first (hat switches excepted).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from devices.base import DeviceError

# -- usage names ---------------------------------------------------------------------------------

GENERIC_DESKTOP = 0x01
SIMULATION = 0x02
BUTTON = 0x09

USAGE_NAMES: dict[tuple[int, int], str] = {
    (GENERIC_DESKTOP, 0x30): "X",
    (GENERIC_DESKTOP, 0x31): "Y",
    (GENERIC_DESKTOP, 0x32): "Z",
    (GENERIC_DESKTOP, 0x33): "Rx",
    (GENERIC_DESKTOP, 0x34): "Ry",
    (GENERIC_DESKTOP, 0x35): "Rz",
    (GENERIC_DESKTOP, 0x36): "Slider",
    (GENERIC_DESKTOP, 0x37): "Dial",
    (GENERIC_DESKTOP, 0x38): "Wheel",
    (GENERIC_DESKTOP, 0x39): "hat",
    (GENERIC_DESKTOP, 0x3D): "Start",
    (GENERIC_DESKTOP, 0x3E): "Select",
    (GENERIC_DESKTOP, 0x40): "Vx",
    (GENERIC_DESKTOP, 0x41): "Vy",
    (GENERIC_DESKTOP, 0x42): "Vz",
    (GENERIC_DESKTOP, 0x01): "pointer",
    (GENERIC_DESKTOP, 0x90): "dpad_up",
    (GENERIC_DESKTOP, 0x91): "dpad_down",
    (GENERIC_DESKTOP, 0x92): "dpad_right",
    (GENERIC_DESKTOP, 0x93): "dpad_left",
    (SIMULATION, 0xBA): "Rudder",
    (SIMULATION, 0xBB): "Throttle",
    (SIMULATION, 0xC4): "Accelerator",
    (SIMULATION, 0xC5): "Brake",
    (SIMULATION, 0xC8): "Steering",
}
"""(usage page, usage) -> channel name; Button page usages are ``button<N>``; others are named by
their page (``PAGE_NAMES``: ``consumer_0224``, ``vendor_ff00_0021``) or ``usage_<page>_<usage>``
in hex. PS3-style pads put their pressure axes under Pointer: ``pointer``, ``pointer_2``, ..."""

PAGE_NAMES = {GENERIC_DESKTOP: "desktop", SIMULATION: "simulation", 0x05: "game", 0x06: "device",
              0x07: "key", 0x08: "led", 0x0C: "consumer", 0x0D: "digitizer", 0x0F: "pid", 0x20: "sensor"}
VENDOR_PAGES = range(0xFF00, 0x10000)

HAT = (GENERIC_DESKTOP, 0x39)


def usage_name(page: int, usage: int) -> str:
    """The channel name of a usage (``X``, ``button3``, ``hat``, ``consumer_0224``, ``vendor_ff00_0020``)."""
    if page == BUTTON:
        return f"button{usage}"
    if (page, usage) in USAGE_NAMES:
        return USAGE_NAMES[(page, usage)]
    if page in PAGE_NAMES:
        return f"{PAGE_NAMES[page]}_{usage:04x}"
    if page in VENDOR_PAGES:
        return f"vendor_{page:04x}_{usage:04x}"
    return f"usage_{page:04x}_{usage:04x}"


# -- the parse -----------------------------------------------------------------------------------

class DescriptorError(DeviceError, ValueError):
    """A report descriptor that cannot be read (names the byte offset)."""


@dataclass(frozen=True)
class ReportField:
    """One Input main item: ``count`` values of ``bit_size`` bits from ``bit_offset`` on.

    ``bit_offset`` counts from the first bit after the report ID byte (when the device numbers its
    reports, ``report_id`` > 0) or from the first bit of the report (``report_id`` == 0).
    ``usages`` are (page, usage) pairs, one per value (the last repeats when there are fewer
    usages than values, as the spec says); empty for an item with no usage.
    """

    report_id: int
    bit_offset: int
    bit_size: int
    count: int
    logical_min: int
    logical_max: int
    usages: tuple[tuple[int, int], ...] = ()
    variable: bool = True
    flags: int = 0x02

    @property
    def signed(self) -> bool:
        return self.logical_min < 0

    def usage(self, i: int) -> tuple[int, int] | None:
        if not self.usages:
            return None
        return self.usages[min(i, len(self.usages) - 1)]


_SIZES = (0, 1, 2, 4)
MAX_REPORT_SIZE = 256
MAX_USAGES = 12288
MAX_REPORT_BYTES = 16384
MAX_DESCRIPTOR_BYTES = 4096  # Linux's HID_MAX_DESCRIPTOR_SIZE; hidapi reads no more either
MAX_PUSH = 4  # Linux's HID_GLOBAL_STACK_SIZE
MAX_INPUT_VALUES = 16384  # all reports together; the most of 135 real descriptors is 5,122 (an N-trig screen)
MAX_KEPT_USAGES = 4 * MAX_USAGES  # all input fields together; the most of the 135 is 13,129 (an ITE keyboard)

# item tags: main (type 0), global (type 1), local (type 2)
_INPUT, _OUTPUT, _COLLECTION, _FEATURE, _END_COLLECTION = 0x8, 0x9, 0xA, 0xB, 0xC
_USAGE_PAGE, _LOGICAL_MIN, _LOGICAL_MAX = 0x0, 0x1, 0x2
_REPORT_SIZE, _REPORT_ID, _REPORT_COUNT, _PUSH, _POP = 0x7, 0x8, 0x9, 0xA, 0xB
_USAGE, _USAGE_MIN, _USAGE_MAX = 0x0, 0x1, 0x2


@dataclass
class _Globals:
    usage_page: int = 0
    logical_min: int = 0
    logical_max: int = 0
    report_size: int = 0
    report_count: int = 0
    report_id: int = 0
    logical_max_size: int = 4  # bytes Logical Maximum was encoded in (for the unsigned fix-up)

    def copy(self) -> _Globals:
        return _Globals(**self.__dict__)


def _signed(value: int, size: int) -> int:
    bits = 8 * size
    return value - (1 << bits) if size and value >> (bits - 1) else value


def parse_descriptor(descriptor: bytes | Sequence[int]) -> list[ReportField]:
    """The input fields a report descriptor declares, in declaration order (padding left out)."""
    data = bytes(descriptor)
    _at_most(len(data), MAX_DESCRIPTOR_BYTES, "a descriptor of", 0, " bytes")
    reader = _Reader()
    for at, prefix, kind, tag, size, value in _items(data):
        if kind == 0:
            reader.main(at, prefix, tag, value)
        elif kind == 1:
            reader.global_item(at, tag, size, value)
        elif kind == 2:
            reader.local_item(at, tag, size, value)
        else:
            warnings.warn(f"report descriptor byte {at}: item 0x{prefix:02x} of the reserved type skipped "
                          "(as Linux skips it)", stacklevel=2)
    return reader.fields


def _items(data: bytes) -> Iterator[tuple[int, int, int, int, int, int]]:
    """(byte offset, prefix, kind, tag, data size, data value) of each short item; long items
    (0xFE) are stepped over."""
    i = 0
    while i < len(data):
        prefix = data[i]
        if prefix == 0xFE:  # long item: 0xFE, data size, long tag, data
            if i + 2 >= len(data):
                raise DescriptorError(f"report descriptor byte {i}: long item cut short")
            i += 3 + data[i + 1]
            continue
        size = _SIZES[prefix & 3]
        if i + 1 + size > len(data):
            raise DescriptorError(f"report descriptor byte {i}: item 0x{prefix:02x} needs {size} data "
                                  f"bytes, {len(data) - i - 1} left")
        yield i, prefix, (prefix >> 2) & 3, prefix >> 4, size, int.from_bytes(data[i + 1:i + 1 + size], "little")
        i += 1 + size


class _Reader:
    """The state of a descriptor read item by item: globals (and their Push stack), the local
    usages since the last main item, the collections open, each report's next bit offset, and
    the fields and usages kept so far (all bounded, see the MAX_ limits)."""

    def __init__(self) -> None:
        self.fields: list[ReportField] = []
        self.g = _Globals()
        self.stack: list[_Globals] = []
        self.usages = _Usages()
        self.usage_min = 0  # as written (Linux pages a range by its Usage Maximum's size), 0 until one is given
        self.depth = 0
        self.offsets: dict[int, int] = {}  # report id -> next input bit offset
        self.values = self.kept = 0  # input values and usages kept, all fields together
        self.uses_ids = False

    def main(self, at: int, prefix: int, tag: int, value: int) -> None:
        if tag == _INPUT:
            self.input(at, value)
        elif tag == _COLLECTION:
            self.depth += 1
        elif tag == _END_COLLECTION:
            if self.depth == 0:
                raise DescriptorError(f"report descriptor byte {at}: End Collection without Collection")
            self.depth -= 1
        elif tag not in (_OUTPUT, _FEATURE):
            warnings.warn(f"report descriptor byte {at}: unknown main item 0x{prefix:02x} skipped "
                          "(as Linux skips it)", stacklevel=3)
        self.usages, self.usage_min = _Usages(), 0  # local items end with every main item

    def input(self, at: int, value: int) -> None:
        g = self.g
        if g.report_id == 0 and self.uses_ids:
            warnings.warn(f"report descriptor byte {at}: an input without a Report ID in a descriptor "
                          "that numbers its reports (no such report arrives)", stacklevel=4)
        logical_max = g.logical_max
        if g.logical_min >= 0 > logical_max:  # 0x25 0xFF meaning 255, a common slip
            logical_max &= (1 << (8 * g.logical_max_size)) - 1
        start = self.offsets.get(g.report_id, 0)
        self.offsets[g.report_id] = start + g.report_size * g.report_count
        if self.offsets[g.report_id] > 8 * MAX_REPORT_BYTES:
            raise DescriptorError(f"report descriptor byte {at}: report {g.report_id} grows to "
                                  f"{self.offsets[g.report_id] // 8:,} bytes, expected at most "
                                  f"{MAX_REPORT_BYTES:,}")
        constant, variable = bool(value & 0x01), bool(value & 0x02)
        if constant or g.report_size == 0 or g.report_count == 0:
            return
        paged = self.usages.paged(g.usage_page, g.report_count if variable else MAX_USAGES)
        self.values += g.report_count
        self.kept += len(paged)
        _at_most(self.values, MAX_INPUT_VALUES, "input values in all", at)
        _at_most(self.kept, MAX_KEPT_USAGES, "input usages in all", at)
        self.fields.append(ReportField(
            report_id=g.report_id, bit_offset=start, bit_size=g.report_size,
            count=g.report_count, logical_min=g.logical_min, logical_max=logical_max,
            usages=paged, variable=variable, flags=value))

    def global_item(self, at: int, tag: int, size: int, value: int) -> None:
        """Usage page, logical range, report size / ID / count, Push and Pop (physical extents,
        unit exponent and unit are not used)."""
        g = self.g
        if tag == _USAGE_PAGE:
            g.usage_page = value
        elif tag == _LOGICAL_MIN:
            g.logical_min = _signed(value, size)
        elif tag == _LOGICAL_MAX:
            g.logical_max = _signed(value, size)
            g.logical_max_size = size
        elif tag == _REPORT_SIZE:
            _at_most(value, MAX_REPORT_SIZE, "Report Size", at)
            g.report_size = value
        elif tag == _REPORT_ID:
            if not 1 <= value <= 255:
                raise DescriptorError(f"report descriptor byte {at}: Report ID {value} (must be 1..255)")
            if not self.uses_ids and self.offsets:
                warnings.warn(f"report descriptor byte {at}: a Report ID after unnumbered inputs "
                              "(no report without an ID arrives)", stacklevel=3)
            self.uses_ids = True
            g.report_id = value
        elif tag == _REPORT_COUNT:
            _at_most(value, MAX_USAGES, "Report Count", at)
            g.report_count = value
        elif tag == _PUSH:
            _at_most(len(self.stack) + 1, MAX_PUSH, "Push nested", at, " deep")
            self.stack.append(g.copy())
        elif tag == _POP:
            if not self.stack:
                raise DescriptorError(f"report descriptor byte {at}: Pop without Push")
            self.g = self.stack.pop()

    def local_item(self, at: int, tag: int, size: int, value: int) -> None:
        """Usages and usage ranges (designators, strings and delimiters are not used)."""
        if tag == _USAGE:
            _at_most(self.usages.count + 1, MAX_USAGES, "usages before a main item", at)
            self.usages.add(value, value, size, self.g.usage_page)
        elif tag == _USAGE_MIN:
            self.usage_min = value
        elif tag == _USAGE_MAX:
            last = min(value, self.usage_min + MAX_USAGES - self.usages.count - 1)
            if last < value:
                warnings.warn(f"report descriptor byte {at}: Usage Maximum 0x{value:x} cut to 0x{last:x}, "
                              f"{MAX_USAGES:,} usages at the most (as Linux cuts it)", stacklevel=3)
            self.usages.add(self.usage_min, last, size, self.g.usage_page)


class _Usages:
    """The usages read since the last main item, as runs (first, last, page) of values as written:
    ``page`` None for 4-byte usages, which carry their own page in the high 16 bits; a shorter
    one's page is the Usage Page in force when it was read, and again at its main item. Runs are
    expanded only for an Input, and only as far as it uses them, so an Output or Feature item
    with a usage range of 12,288 costs nothing."""

    def __init__(self) -> None:
        self.runs: list[tuple[int, int, int | None]] = []
        self.count = 0

    def add(self, first: int, last: int, size: int, page: int) -> None:
        if last >= first:
            self.runs.append((first, last, None if size == 4 else page))
            self.count += last - first + 1

    def paged(self, page: int, limit: int) -> tuple[tuple[int, int], ...]:
        """The first ``limit`` (page, usage) pairs, the short usages read since the last one on
        ``page`` (the Usage Page in force at their main item) moved onto it, as Linux's
        hid_concatenate_last_usage_page does."""
        runs = list(self.runs)
        for i in range(len(runs) - 1, -1, -1):
            first, last, own = runs[i]
            if own is not None and own == page:
                break
            if own is not None:
                runs[i] = (first, last, page)
        out: list[tuple[int, int]] = []
        for first, last, own in runs:
            stop = min(last + 1, first + limit - len(out))
            out.extend((u >> 16, u & 0xFFFF) if own is None else (own, u) for u in range(first, stop))
            if len(out) >= limit:
                break
        return tuple(out)


def _at_most(value: int, limit: int, what: str, at: int, unit: str = "") -> None:
    if value > limit:
        raise DescriptorError(f"report descriptor byte {at}: {what} {value:,}{unit}, expected at most "
                              f"{limit:,}{unit}")


# -- channels and extraction ---------------------------------------------------------------------

AXIS, BUTTON_KIND, HAT_KIND, RAW = "axis", "button", "hat", "raw"


@dataclass(frozen=True)
class Channel:
    """One value in a report: where it is, how wide, its logical range and how it is scaled."""

    name: str
    report_id: int
    bit_offset: int
    bit_size: int
    logical_min: int
    logical_max: int
    kind: str = AXIS

    @property
    def signed(self) -> bool:
        return self.logical_min < 0


def channels_of(fields: Iterable[ReportField]) -> list[Channel]:
    """One Channel per value of the fields, named by usage; a repeated name gets ``_2``, ``_3``."""
    out: list[Channel] = []
    seen: dict[str, int] = {}
    arrays = 0
    for f in fields:
        if f.bit_size > 32:
            continue
        for k in range(f.count):
            usage = f.usage(k)
            if not f.variable:
                arrays += 1
                name, kind = f"array{arrays}", RAW
            elif usage is None:
                name, kind = "unnamed", AXIS
            else:
                name = usage_name(*usage)
                kind = (BUTTON_KIND if usage[0] == BUTTON or f.bit_size == 1
                        else HAT_KIND if usage == HAT else AXIS)
            seen[name] = seen.get(name, 0) + 1
            if seen[name] > 1:
                name = f"{name}_{seen[name]}"
            out.append(Channel(name, f.report_id, f.bit_offset + k * f.bit_size, f.bit_size,
                               f.logical_min, f.logical_max, kind))
    return out


class ReportDecoder:
    """The channels of one report ID, compiled for cheap extraction of one report or many.

    ``data`` is the report without its ID byte. One report: the bytes become one Python integer
    (little-endian, as HID packs bits: bit 0 is the least significant bit of byte 0), and each
    channel is a shift and a mask, then a sign extension and a scale. Many reports at once
    (``decode_array``): the same in numpy over a (reports, bytes) array.
    """

    def __init__(self, channels: Sequence[Channel], raw: bool = False) -> None:
        self.channels = list(channels)
        self.names = [c.name for c in self.channels]
        self.raw = raw
        self.length = max(((c.bit_offset + c.bit_size + 7) // 8 for c in self.channels), default=0)
        plan = []
        for c in self.channels:
            mask = (1 << c.bit_size) - 1
            sign = (1 << (c.bit_size - 1)) if c.signed else 0
            lo, hi = c.logical_min, c.logical_max
            if c.kind == BUTTON_KIND:
                mode, a, b = 1, 0.0, 0.0
            elif c.kind == HAT_KIND:
                mode, a, b = 2, 360.0 / (hi - lo + 1) if hi >= lo else 0.0, 0.0
            elif c.kind == RAW:
                mode, a, b = 3, 0.0, 0.0
            elif lo < 0:
                mode, a, b = 4, 1.0 / hi if hi > 0 else 0.0, 1.0 / -lo
            else:
                mode, a, b = 5, 1.0 / (hi - lo) if hi > lo else 0.0, 0.0
            if raw:
                mode = 3
            plan.append((c.name, c.bit_offset, mask, sign, lo, hi, mode, a, b))
        self._plan = plan

    def decode(self, data: bytes) -> dict[str, float]:
        """The channel values of one report's data (at least ``self.length`` bytes)."""
        bits = int.from_bytes(data, "little")
        out = {}
        for name, offset, mask, sign, lo, hi, mode, a, b in self._plan:
            v = (bits >> offset) & mask
            if sign and v & sign:
                v -= sign << 1
            if mode == 1:
                out[name] = 1.0 if v else 0.0
            elif mode == 3:
                out[name] = float(v)
            elif mode == 2:
                out[name] = (v - lo) * a if lo <= v <= hi else -1.0
            else:
                v = lo if v < lo else hi if v > hi else v
                out[name] = v * (a if v >= 0 else b) if mode == 4 else (v - lo) * a
        return out

    def encode(self, values: Mapping[str, float]) -> bytes:
        """Report data (no ID byte) that ``decode`` turns back into ``values``: the inverse of the
        scaling, for replaying logged readings as reports (``devices.simulated_hid.HidTwin``).
        Each value becomes the nearest raw value in its field (clamped to the logical range, as
        ``decode`` clamps); a value that no raw value decodes to exactly therefore comes back
        different, which the caller checks. Padding and constant bits are 0. ValueError names a
        channel ``values`` lacks; a non-finite value raises ValueError or OverflowError."""
        bits = 0
        for c in self.channels:
            if c.name not in values:
                raise ValueError(f"report {c.report_id} needs a value for channel {c.name!r}")
            raw = self._raw(c, float(values[c.name]))
            bits |= (raw & ((1 << c.bit_size) - 1)) << c.bit_offset
        return bits.to_bytes(self.length, "little")

    def _raw(self, c: Channel, value: float) -> int:
        """The raw field value that ``decode`` scales to ``value`` (or nearest to it)."""
        lo, hi = c.logical_min, c.logical_max
        field_lo, field_hi = (-(1 << (c.bit_size - 1)), (1 << (c.bit_size - 1)) - 1) if c.signed \
            else (0, (1 << c.bit_size) - 1)
        if self.raw or c.kind == RAW:
            return _clamp(round(value), field_lo, field_hi)
        if c.kind == BUTTON_KIND:
            return 1 if value else 0
        if c.kind == HAT_KIND:
            if value == -1.0:  # centred: any value outside the logical range that fits the field
                return hi + 1 if hi < field_hi else lo - 1 if lo > field_lo else lo
            return _clamp(lo + round(value * (hi - lo + 1) / 360.0), lo, hi)
        if lo < 0:
            raw = round(value * hi) if value >= 0 else round(value * -lo)
        else:
            raw = lo + round(value * (hi - lo))
        return _clamp(raw, lo, hi)

    def decode_array(self, reports: np.ndarray) -> np.ndarray:
        """Channel values of many reports' data at once: (n, >= length) uint8 -> (n, channels)."""
        reports = np.asarray(reports, dtype=np.uint8)
        n = reports.shape[0]
        if not self.channels:
            return np.zeros((n, 0))
        offsets = np.array([c.bit_offset for c in self.channels])
        sizes = np.array([c.bit_size for c in self.channels])
        first = offsets // 8
        span = np.arange(5)  # 32 bits + 7 bits of offset fit in 5 bytes
        idx = first[:, None] + span[None, :]
        valid = idx < reports.shape[1]
        gathered = reports[:, np.where(valid, idx, 0)].astype(np.uint64) * valid
        words = (gathered << (np.uint64(8) * span.astype(np.uint64))).sum(axis=2, dtype=np.uint64)
        masks = ((np.uint64(1) << sizes.astype(np.uint64)) - np.uint64(1))
        v = ((words >> (offsets % 8).astype(np.uint64)) & masks).astype(np.int64)
        signed = np.array([c.signed for c in self.channels])
        top = np.int64(1) << (sizes - 1).astype(np.int64)
        v = np.where(signed & (v & top != 0), v - (top << 1), v)
        if self.raw:
            raw: np.ndarray = v.astype(np.float64)
            return raw
        lo = np.array([c.logical_min for c in self.channels])
        hi = np.array([c.logical_max for c in self.channels])
        kinds = np.array([c.kind for c in self.channels])
        out = np.empty(v.shape)
        clamped = np.clip(v, lo, hi).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            span_u = np.where(hi > lo, 1.0 / np.maximum(hi - lo, 1), 0.0)
            pos = np.where(hi > 0, 1.0 / np.maximum(hi, 1), 0.0)
            neg = np.where(lo < 0, 1.0 / np.maximum(-lo, 1), 0.0)
        axis_signed = np.where(clamped >= 0, clamped * pos, clamped * neg)
        axis_unsigned = (clamped - lo) * span_u
        out[:] = np.where(lo < 0, axis_signed, axis_unsigned)
        button = kinds == BUTTON_KIND
        out[:, button] = (v[:, button] != 0)
        raw_kind = kinds == RAW
        out[:, raw_kind] = v[:, raw_kind]
        hat = kinds == HAT_KIND
        if hat.any():
            hv, hlo, hhi = v[:, hat], lo[hat], hi[hat]
            step = 360.0 / np.maximum(hhi - hlo + 1, 1)
            out[:, hat] = np.where((hv >= hlo) & (hv <= hhi), (hv - hlo) * step, -1.0)
        return out


def _clamp(value: int, lo: int, hi: int) -> int:
    return lo if value < lo else hi if value > hi else value


class ReportLayout:
    """Every input channel of a device, by report ID, and the decoding of raw reports.

    ``numbered`` says whether reports start with a report ID byte (true when any channel has a
    report ID above 0: a device numbers all its reports or none, so then report 0's channels,
    which no report carries, are left out).
    """

    def __init__(self, channels: Sequence[Channel], raw: bool = False) -> None:
        self.numbered = any(c.report_id for c in channels)
        self.channels = [c for c in channels if c.report_id or not self.numbered]
        by_id: dict[int, list[Channel]] = {}
        for c in self.channels:
            by_id.setdefault(c.report_id, []).append(c)
        self.decoders = {rid: ReportDecoder(chs, raw) for rid, chs in by_id.items()}
        self.names = [c.name for c in self.channels]
        self.report_length = max((d.length + self.numbered for d in self.decoders.values()), default=0)

    @classmethod
    def from_descriptor(cls, descriptor: bytes | Sequence[int], raw: bool = False) -> ReportLayout:
        return cls(channels_of(parse_descriptor(descriptor)), raw)

    def encode(self, values: Mapping[str, float]) -> bytes:
        """The raw report (with its ID byte when numbered) that ``decode`` turns back into
        ``values``, which must hold exactly the channels of one report ID (as ``decode`` returns
        them); see ``ReportDecoder.encode``. ValueError when no report carries those channels."""
        for report_id, decoder in self.decoders.items():
            if set(decoder.names) == set(values):
                prefix = bytes([report_id]) if self.numbered else b""
                return prefix + decoder.encode(values)
        raise ValueError(f"no input report carries exactly the channels {sorted(values)}")

    def decode(self, report: bytes, has_id: bool | None = None) -> dict[str, float] | None:
        """The channel values of one raw report, or None if it is not one this layout knows
        (unknown report ID, or shorter than its fields need). ``has_id`` says whether ``report``
        starts with its report ID byte (default: whether this layout numbers its reports)."""
        if has_id is None:
            has_id = self.numbered
        if has_id:
            if not report:
                return None
            decoder = self.decoders.get(report[0])
            data = report[1:]
        else:
            decoder = self.decoders.get(0) or (next(iter(self.decoders.values())) if len(self.decoders) == 1 else None)
            data = report
        if decoder is None or len(data) < decoder.length:
            return None
        return decoder.decode(data)


@dataclass(frozen=True)
class FieldSpec:
    """A channel given by hand (URL option or mapping) for devices whose descriptor is not read."""

    name: str
    bit_offset: int
    bit_size: int
    logical_min: int = 0
    logical_max: int | None = None
    kind: str | None = None
    report_id: int = 0
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    def channel(self) -> Channel:
        hi = self.logical_max if self.logical_max is not None else (1 << self.bit_size) - 1
        kind = self.kind or (BUTTON_KIND if self.bit_size == 1 or self.name.startswith("button")
                             else HAT_KIND if self.name == "hat" else AXIS)
        return Channel(self.name, self.report_id, self.bit_offset, self.bit_size, self.logical_min, hi, kind)

    @classmethod
    def parse(cls, text: str, report_id: int = 0) -> FieldSpec:
        """``name:bit_offset:bit_size[:logical_min:logical_max[:kind]]`` (kind: axis, button, hat, raw)."""
        parts = text.strip().split(":")
        if len(parts) not in (3, 5, 6):
            raise ValueError(f"HID field {text!r}: expected name:bit_offset:bit_size[:min:max[:kind]]")
        try:
            name, offset, size = parts[0], int(parts[1], 0), int(parts[2], 0)
            lo, hi = (int(parts[3], 0), int(parts[4], 0)) if len(parts) >= 5 else (0, None)
        except ValueError:
            raise ValueError(f"HID field {text!r}: offsets, sizes and limits must be integers") from None
        kind = parts[5] if len(parts) == 6 else None
        if kind not in (None, AXIS, BUTTON_KIND, HAT_KIND, RAW):
            raise ValueError(f"HID field {text!r}: kind {kind!r} is not one of axis, button, hat, raw")
        if not name or not 1 <= size <= 32 or offset < 0:
            raise ValueError(f"HID field {text!r}: needs a name, an offset >= 0 and a size of 1..32 bits")
        return cls(name, offset, size, lo, hi, kind, report_id)
