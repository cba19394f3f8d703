"""Real report descriptors parse as Linux reads them, field for field as hid-tools parses them,
and no descriptor can make the parser allocate or run without bound."""

from __future__ import annotations

import os
import struct
import time
import tracemalloc
import warnings
from collections import Counter
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from devices.hid_descriptor import MAX_USAGES, DescriptorError, ReportLayout, parse_descriptor

DESCRIPTORS = sorted((Path(__file__).parent / "data" / "hid").glob("*.hex"))
TALLY: Counter = Counter()
SCALE = int(os.environ.get("PUPPET_FUZZ_SCALE", "1"))
SLOWEST_MS = 0.0


def _bytes(path: Path) -> bytes:
    return bytes.fromhex(path.read_text())


def _quiet(action):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return action()


def _ours(data: bytes) -> list[tuple]:
    """One row per input value: report, bit offset, size, logical range, usage (arrays: all)."""
    rows = []
    for f in _quiet(lambda: parse_descriptor(data)):
        full = tuple((p << 16) | u for p, u in f.usages)
        for k in range(f.count):
            usage = ("array", full) if not f.variable else (((f.usage(k)[0] << 16) | f.usage(k)[1]) if f.usages else None,)
            rows.append((f.report_id, f.bit_offset + k * f.bit_size, f.bit_size, f.logical_min, f.logical_max) + usage)
    return sorted(rows)


def _hid_tools(data: bytes) -> list[tuple]:
    from hidtools.hid import ReportDescriptor

    rows = []
    for report in ReportDescriptor.from_bytes(data).input_reports.values():
        start = 8 if report.numbered else 0
        for f in report.fields:
            if f.is_const:
                continue
            for k in range(f.count):
                usage = ("array", tuple(f.usages or ())) if f.is_array else (f.usage,)
                rows.append((report.report_ID if report.numbered else 0, f.start - start + k * f.size, f.size,
                             f.logical_min, f.logical_max) + usage)
    return sorted(rows)


HID_TOOLS_DIFFERS = {"xpadneo_gamesir_g7_se_2"}
"""Where hid-tools reads otherwise than Linux: a 1-byte Usage Minimum 0 with a 4-byte Usage Maximum
0x0000FFFF (a consumer key array). hid-tools pages the minimum and finds the range empty; Linux runs
it over the values as written, paged by the maximum's size (page 0), cut to 12,288 usages. We read
it as Linux does; every other field of it matches."""


def test_there_are_real_descriptors_to_read():
    assert len(DESCRIPTORS) >= 135
    assert {"xpadneo_xb1s_linux", "xpadneo_xbe2_linux", "xpadneo_xbe2_unknown",
            "xpadneo_8bitso_sn30_windows"} <= {p.stem for p in DESCRIPTORS}


@pytest.mark.parametrize("path", [p for p in DESCRIPTORS if p.stem not in HID_TOOLS_DIFFERS], ids=lambda p: p.stem)
def test_a_real_descriptor_parses_field_for_field_as_hid_tools(path):
    pytest.importorskip("hidtools", reason="hid-tools (the test extra) compares the fields")
    data = _bytes(path)
    assert _ours(data) == _hid_tools(data)


def test_where_hid_tools_departs_from_linux_the_rest_still_matches_and_the_range_reads_as_linux():
    pytest.importorskip("hidtools", reason="hid-tools (the test extra) compares the fields")
    data = _bytes(Path(__file__).parent / "data" / "hid" / "xpadneo_gamesir_g7_se_2.hex")
    ours, theirs = _ours(data), _hid_tools(data)
    differ = [(a, b) for a, b in zip(ours, theirs) if a != b]
    assert len(ours) == len(theirs) and len(differ) == 2
    for a, b in differ:
        assert a[:6] == b[:6] == (2, a[1], 16, 0, 65535, "array")
        assert b[6] == () and a[6] == tuple(range(MAX_USAGES))  # page 0, usages 0..12287


def test_a_usage_range_is_paged_by_its_maximum_and_a_maximum_alone_starts_from_0():
    def usages(items: str) -> tuple:
        data = bytes.fromhex("05 0c 09 01 a1 01" + items + "75 08 95 01 15 00 26 ff 00 81 00 c0")
        (field,) = _quiet(lambda: parse_descriptor(data))
        return field.usages

    assert usages("19 01 29 03") == ((0x0C, 1), (0x0C, 2), (0x0C, 3))
    assert usages("1b 01 00 09 00 29 03") == ()  # 4-byte minimum above a short maximum: empty, as Linux
    assert usages("19 01 2b 03 00 00 00") == ((0, 1), (0, 2), (0, 3))  # a 4-byte maximum: its own page
    assert usages("29 02") == ((0x0C, 0), (0x0C, 1), (0x0C, 2))


@pytest.mark.parametrize("name", ["xpadneo_xb1s_linux", "xpadneo_xbe2_linux", "xpadneo_xbe2_unknown",
                                  "xpadneo_8bitso_sn30_windows"])
def test_pads_whose_descriptor_ends_in_a_stray_zero_byte_get_their_sticks(name):
    data = _bytes(Path(__file__).parent / "data" / "hid" / f"{name}.hex")
    with pytest.warns(UserWarning, match="unknown main item 0x00 skipped"):
        layout = ReportLayout.from_descriptor(data + b"\x00")
    assert {"X", "Y", "button1"} <= set(layout.names)


def test_ps3_and_vendor_axes_are_named_by_their_usage():
    names = set(_quiet(lambda: ReportLayout.from_descriptor(
        _bytes(Path(__file__).parent / "data" / "hid" / "hidtools_sony_gamepad_PS3Controller.hex"))).names)
    assert {"pointer", "pointer_2"} <= names
    ps4 = set(_quiet(lambda: ReportLayout.from_descriptor(
        _bytes(Path(__file__).parent / "data" / "hid" / "hidtools_sony_gamepad_PS4ControllerUSB.hex"))).names)
    assert "vendor_ff00_0020" in ps4 and not any(n.startswith("usage_") for n in names | ps4)


def test_a_usage_page_before_the_input_repages_its_short_usages():
    # keyboard LED output on page 8, then keys: Usage Minimum/Maximum read on page 8, Usage Page 7
    data = bytes.fromhex("05 01 09 06 a1 01 05 08 19 00 2a ff 00 05 07 75 08 95 01 15 00 26 ff 00 81 00 c0")
    (field,) = parse_descriptor(data)
    assert field.usages[0] == (0x07, 0) and field.usages[-1] == (0x07, 0xFF)


def _global(tag: int, value: int) -> bytes:
    return bytes([tag | 0x03]) + struct.pack("<I", value)


BOMBS = {
    "Report Count 0xFFFFFFFF": (bytes.fromhex("05 01 09 05 a1 01 75 08") + _global(0x94, 0xFFFFFFFF)
                                + bytes.fromhex("81 02 c0"), "Report Count 4,294,967,295, expected at most 12,288"),
    "Report Size 0xFFFFFFFF": (_global(0x74, 0xFFFFFFFF) + bytes.fromhex("95 01 81 02"),
                               "Report Size 4,294,967,295, expected at most 256"),
    "a report of 4 MB": (bytes.fromhex("75 ff 96 00 30 81 02") * 20, "expected at most 16,384"),
    # 456 bytes: 20 reports of 122,880 one-bit values each, every report within its bound
    # (2.5 million channels, 1 GB and minutes before the bound on them all)
    "2.5 million values in 20 reports": (
        bytes.fromhex("05 01 09 05 a1 01 75 01 96 00 30 15 00 25 01")
        + b"".join(bytes([0x85, n]) + bytes.fromhex("81 02") * 10 for n in range(1, 21)) + b"\xc0",
        "input values in all 24,576, expected at most 16,384"),
    # 716 bytes: a full usage range for each of 100 one-value array fields (1.2 million usages kept)
    "a usage range in every field": (
        bytes.fromhex("05 0c 09 01 a1 01 75 08 95 01 15 00 26 ff 00")
        + bytes.fromhex("19 00 2a ff 2f 81 00") * 100 + b"\xc0",
        "input usages in all 61,440, expected at most 49,152"),
    # 1 MB of Push: 144 MB of saved globals and 105 s before the bounds (Linux's: 4,096 bytes, 4 deep)
    "1 MB of Push": (b"\xa4" * 1_000_000, "a descriptor of 1,000,000 bytes, expected at most 4,096 bytes"),
    "Push nested 5 deep": (b"\xa4" * 5, "byte 4: Push nested 5 deep, expected at most 4 deep"),
}

SLOW = [bytes.fromhex("19 00 2a ff ff b1 02") * 585]
"""Descriptors that once took seconds, not memory: 4 KB of Feature items each with a full usage
range expanded 7 million usages only to drop them (6 s); usages are now expanded for inputs alone."""


@pytest.mark.parametrize("what", BOMBS)
def test_a_descriptor_cannot_make_the_parser_allocate_without_bound(what):
    data, message = BOMBS[what]
    tracemalloc.start()
    try:
        with pytest.raises(DescriptorError, match=message):
            parse_descriptor(data)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peak < 16_000_000  # the last two held 1 GB or more before their bounds


def test_repeated_full_vendor_usage_ranges_are_cut_as_linux_cuts_them():
    data = bytes.fromhex("06 00 ff 09 01 a1 01") + bytes.fromhex("19 00 2a ff ff") * 100 \
        + bytes.fromhex("75 08 95 01 15 00 26 ff 00 81 00 c0")  # 519 bytes: 1.4 GB of usages unbounded
    tracemalloc.start()
    with pytest.warns(UserWarning, match="cut"):
        (field,) = parse_descriptor(data)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert len(field.usages) == MAX_USAGES and peak < 20_000_000


@st.composite
def mutated(draw) -> bytes:
    data = bytearray(_bytes(draw(st.sampled_from(DESCRIPTORS))))
    for _ in range(draw(st.integers(1, 6))):
        at = draw(st.integers(0, len(data) - 1))
        data[at] = draw(st.integers(0, 255))
    cut = draw(st.integers(0, len(data)))
    return bytes(data[:cut]) if draw(st.booleans()) else bytes(data)


@pytest.fixture(scope="module", autouse=True)
def report():
    yield
    print("\nfuzz tally:", dict(sorted(TALLY.items())))
    print("fuzz slowest ms:", {"hid descriptor": round(SLOWEST_MS, 1)})


@settings(max_examples=400 * SCALE, deadline=5000, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.one_of(st.binary(max_size=600), mutated(), st.sampled_from(SLOW + [d for d, _ in BOMBS.values()])))
def test_any_bytes_as_a_descriptor_read_or_refused_in_bounded_memory(data):
    """Random bytes and real descriptors with bytes changed: a layout that decodes a report of
    zeros, or a DescriptorError; nothing else, and a bounded memory peak."""
    global SLOWEST_MS
    tracemalloc.start()
    start = time.perf_counter()
    try:
        layout = _quiet(lambda: ReportLayout.from_descriptor(data))
        for report_id in layout.decoders:
            layout.decode(bytes([report_id]) + bytes(layout.report_length))
        TALLY["hid descriptor: read"] += 1
    except DescriptorError:
        TALLY["hid descriptor: documented error"] += 1
    except Exception:
        TALLY["hid descriptor: other"] += 1
        raise
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        SLOWEST_MS = max(SLOWEST_MS, 1000 * (time.perf_counter() - start))
    if peak >= 64_000_000:
        TALLY["hid descriptor: over the memory bound"] += 1
    assert peak < 64_000_000
