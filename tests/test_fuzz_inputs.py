"""Fuzzing what users, devices and other programs hand us: arbitrary bytes and near-valid .fap
files, mappings, serial byte streams, OSC datagrams, the control API's messages and OSC control
addresses, and take folders with a part garbled (HID
descriptors: tests/test_hid_descriptors.py). Only documented errors may come out (``PuppetError`` and its
subclasses; ``MappingError`` and ``DeviceError`` for a take's mapping and devices), each input in
bounded time (hypothesis's deadline) and bounded memory (tracemalloc's peak). Set
PUPPET_FUZZ_SCALE (default 1) to multiply the examples; ``-s`` prints the tally. ``tools/checks/fuzz.py``
runs these same properties for as long as it is given and prints the counts."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
import tracemalloc
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from devices.base import DeviceError
from devices.osc_packet import parse_datagram
from devices.serial_wire import (
    MAX_FRAME,
    MAX_LINE,
    encode_ascii_line,
    encode_cobs_frame,
    encode_slip_frame,
    make_parser,
)
from puppet.errors import PuppetError
from puppet.io.fapfile import read_fap, write_fap
from puppet.io.shipped import shipped_mappings
from puppet.io.takes import open_take
from puppet.live.arkit import import_csv
from puppet.live.mappingfile import MappingError, load_mapping, parse_mapping
from puppet.live.retake import retake
from puppet.show import api, osccontrol
from puppet.view.rendertake import FapPlayback

DOCUMENTED = (PuppetError, MappingError, DeviceError)
MEMORY_BOUND = 32_000_000
SCALE = int(os.environ.get("PUPPET_FUZZ_SCALE", "1"))
TALLY: Counter = Counter()
SLOWEST_MS: dict[str, float] = {}


@pytest.fixture(scope="module", autouse=True)
def report():
    yield
    print("\nfuzz tally:", dict(sorted(TALLY.items())))
    print("fuzz slowest ms:", {kind: round(ms, 1) for kind, ms in sorted(SLOWEST_MS.items())})


def _bounded(kind: str, action) -> object:
    """Run ``action``; count what came out (read, documented error, or anything else, which fails);
    fail on a memory peak past ``MEMORY_BOUND`` too."""
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = action()
        TALLY[f"{kind}: read"] += 1
    except DOCUMENTED:
        TALLY[f"{kind}: documented error"] += 1
        result = None
    except Exception:
        TALLY[f"{kind}: other"] += 1
        raise
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        SLOWEST_MS[kind] = max(SLOWEST_MS.get(kind, 0.0), 1000 * (time.perf_counter() - start))
    if peak >= MEMORY_BOUND:
        TALLY[f"{kind}: over the memory bound"] += 1
    assert peak < MEMORY_BOUND, f"{kind}: {peak:,} bytes at the peak"
    return result


# -- .fap files -------------------------------------------------------------------------------------

@settings(max_examples=150 * SCALE, deadline=3000, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.binary(max_size=3000))
def test_arbitrary_bytes_as_a_fap_file(data):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "x.fap"
        path.write_bytes(data)
        stream = _bounded("fap bytes", lambda: read_fap(path))
    if stream is not None:
        assert np.isfinite(stream.values).all()


NASTY = ["1_000", "inf", "-inf", "nan", "1e400", "1e20", "-1e300", "\u0661\u0662", "0x10", "+", "-", ".",
         "1e", "#", "1" * 500, "9" * 30, "2.5", "-0", "\x00", "1,5", "٣", "1e-300", "69", "0 0", ""]


@st.composite
def near_valid_fap(draw) -> bytes:
    """A valid take (FAP 1/2 fields included) with a few lines or tokens spoiled or cut."""
    frames = draw(st.integers(0, 6))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    values = rng.integers(-3000, 3000, size=(frames, 68)).astype(float)
    mask = rng.random((frames, 68)) < 0.5
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "v.fap"
        write_fap(path, (values, mask), fps=draw(st.sampled_from([25, 30, 60])))
        lines = path.read_text().split("\n")
    for _ in range(draw(st.integers(1, 4))):
        how = draw(st.sampled_from(["token", "drop line", "double line", "insert", "header", "cut"]))
        at = draw(st.integers(0, max(len(lines) - 1, 0)))
        tokens = lines[at].split(" ") if lines else []
        if how == "token" and tokens:
            tokens[draw(st.integers(0, len(tokens) - 1))] = draw(st.sampled_from(NASTY))
            lines[at] = " ".join(tokens)
        elif how == "drop line" and lines:
            del lines[at]
        elif how == "double line" and lines:
            lines.insert(at, lines[at])
        elif how == "insert":
            lines.insert(at, draw(st.text(max_size=80)))
        elif how == "header" and lines:
            head = lines[0].split()
            if len(head) >= 4:
                head[draw(st.integers(0, len(head) - 1))] = draw(st.sampled_from(NASTY + ["1" + "0" * 100]))
            lines[0] = " ".join(head)
        elif how == "cut":
            text = "\n".join(lines)
            lines = text[:draw(st.integers(0, len(text)))].split("\n")
    return "\n".join(lines).encode("utf-8", "surrogatepass")


@settings(max_examples=150 * SCALE, deadline=3000, suppress_health_check=[HealthCheck.too_slow])
@given(data=near_valid_fap())
def test_near_valid_fap_files(data):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "x.fap"
        path.write_bytes(data)
        stream = _bounded("fap near-valid", lambda: read_fap(path))
        if stream is not None:  # what reads back also writes back, unchanged
            assert np.isfinite(stream.values).all()
            again = Path(folder) / "again.fap"
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # a fractional fps is written rounded, with a warning
                write_fap(again, stream)
                back = read_fap(again)
            np.testing.assert_array_equal(back.values, np.rint(stream.values) + 0.0)


# -- mappings ---------------------------------------------------------------------------------------

MAPPING_NASTY = ["1e400", "1e308", "-1e308", "1e-320", ".nan", ".inf", "1_000", "&a [*a, *a]", "*nowhere",
                 "!!python/object:os.system", "{", "[", "'", "\t", "~", "[]", "{}", "yes", "0x1F", "9" * 5000]


def _seed_mappings() -> list[list[str]]:
    """The shipped mappings' lines, an ARKit mapping's targets (1,234 of one shape) cut to their
    first 20 and last 10: every key, kind and comment it has at a 40th of the parse, and a
    spoiled line lands in its devices and channels as often as in its targets."""
    seeds = []
    for path in sorted(shipped_mappings().values()):
        lines = path.read_text("utf-8").split("\n")
        start = lines.index("targets:") + 1
        seeds.append(lines[:start + 20] + lines[-10:] if len(lines) - start > 40 else lines)
    return seeds


MAPPING_SEEDS = _seed_mappings()


@st.composite
def near_valid_mapping(draw) -> str:
    """A shipped mapping with a few lines spoiled, cut, repeated or given nasty values."""
    lines = list(draw(st.sampled_from(MAPPING_SEEDS)))
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(lines) - 1))
        how = draw(st.sampled_from(["value", "drop", "double", "indent", "insert"]))
        if how == "value" and ":" in lines[at]:
            lines[at] = lines[at].split(":", 1)[0] + ": " + draw(st.sampled_from(MAPPING_NASTY))
        elif how == "drop":
            del lines[at]
        elif how == "double":
            lines.insert(at, lines[at])
        elif how == "indent":
            lines[at] = " " * draw(st.integers(0, 9)) + lines[at].lstrip()
        else:
            lines.insert(at, draw(st.text(max_size=60)))
    return "\n".join(lines)


@settings(max_examples=150 * SCALE, deadline=5000, suppress_health_check=[HealthCheck.too_slow])
@given(text=st.one_of(st.text(max_size=400), near_valid_mapping(), st.binary(max_size=400)))
def test_mapping_text(text):
    """Text through ``parse_mapping``; bytes (not UTF-8, as often as not) through a file and
    ``load_mapping``."""
    if isinstance(text, str):
        _bounded("mapping", lambda: parse_mapping(text, "fuzz.yaml"))
        return
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "fuzz.yaml"
        path.write_bytes(text)
        _bounded("mapping", lambda: load_mapping(path))


# -- serial byte streams ------------------------------------------------------------------------------

@st.composite
def serial_stream(draw) -> tuple[str, list[bytes]]:
    """A protocol and the chunks a port hands over: valid frames and lines, garbage, cuts, floods."""
    protocol = draw(st.sampled_from(["ascii", "ascii nmea", "cobs", "slip"]))
    parts = []
    for _ in range(draw(st.integers(1, 12))):
        how = draw(st.sampled_from(["good", "garbage", "flood", "flip"]))
        values = draw(st.lists(st.floats(-1000, 1000), min_size=1, max_size=8))
        good = (encode_ascii_line(values, checksum="nmea" if protocol == "ascii nmea" else "none")
                if protocol.startswith("ascii")
                else encode_cobs_frame(values) if protocol == "cobs" else encode_slip_frame(values))
        if how == "good":
            parts.append(good)
        elif how == "garbage":
            parts.append(draw(st.binary(max_size=200)))
        elif how == "flood":
            parts.append(bytes([draw(st.integers(1, 255))]) * (2 * max(MAX_LINE, MAX_FRAME)))
        else:
            flipped = bytearray(good)
            flipped[draw(st.integers(0, len(flipped) - 1))] ^= 1 << draw(st.integers(0, 7))
            parts.append(bytes(flipped))
    stream = b"".join(parts)
    cuts = sorted(draw(st.lists(st.integers(0, len(stream)), max_size=6)))
    return protocol, [stream[a:b] for a, b in zip([0] + cuts, cuts + [len(stream)])]


@settings(max_examples=200 * SCALE, deadline=3000, suppress_health_check=[HealthCheck.too_slow])
@given(case=serial_stream())
def test_serial_framing(case):
    """Every chunk read or counted as bad; readings hold finite numbers only."""
    protocol, chunks = case
    parser = make_parser(protocol.split()[0], checksum="nmea" if protocol == "ascii nmea" else "none")

    def feed() -> list:
        return [reading for chunk in chunks for reading in parser.feed(chunk)]

    for reading in _bounded(f"serial {protocol}", feed) or []:
        assert all(np.isfinite(v) for v in reading.values())
    TALLY[f"serial {protocol}: bad frames skipped"] += parser.bad


# -- OSC datagrams -------------------------------------------------------------------------------------

def _osc_message(address: bytes, tags: bytes, payload: bytes) -> bytes:
    def padded(raw: bytes) -> bytes:
        return raw + b"\0" * (4 - len(raw) % 4)
    return padded(address) + padded(tags) + payload


OSC_SEEDS = [
    _osc_message(b"/fader/1", b",f", b"\x3f\x00\x00\x00"),
    _osc_message(b"/VMC/Ext/Blend/Val", b",sf", b"JawOpen\0\x3f\x00\x00\x00"),
    b"#bundle\0" + bytes(8) + b"\0\0\0\x10" + _osc_message(b"/x", b",i", b"\0\0\0\1"),
]


@st.composite
def near_valid_datagram(draw) -> bytes:
    data = bytearray(draw(st.sampled_from(OSC_SEEDS)))
    for _ in range(draw(st.integers(1, 4))):
        data[draw(st.integers(0, len(data) - 1))] = draw(st.integers(0, 255))
    return bytes(data[:draw(st.integers(0, len(data)))])


@settings(max_examples=300 * SCALE, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
@given(datagram=st.one_of(st.binary(max_size=600), near_valid_datagram()))
def test_osc_datagrams(datagram):
    _bounded("osc datagram", lambda: parse_datagram(datagram))


# -- the control API's messages and OSC control addresses -------------------------------------------

API_SEEDS = ['{"type": "status", "id": 1}', '{"type": "set", "channels": {"smile": 0.8}}',
             '{"type": "trigger", "name": "wow", "action": "press"}', '{"type": "record", "action": "start"}',
             '{"type": "subscribe", "interval": 0.5}', '{"type": "takes"}', '{"type": "neutral"}']


@st.composite
def near_valid_api_message(draw) -> str:
    text = list(draw(st.sampled_from(API_SEEDS)))
    for _ in range(draw(st.integers(0, 3))):
        text[draw(st.integers(0, len(text) - 1))] = draw(st.characters())
    return "".join(text[:draw(st.one_of(st.just(len(text)), st.integers(0, len(text))))])


@settings(max_examples=400 * SCALE, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
@given(message=st.one_of(st.text(max_size=400), st.binary(max_size=200), near_valid_api_message()))
def test_api_messages(message):
    _bounded("api message", lambda: api.parse(message))


OSC_CONTROL_SEEDS = [_osc_message(b"/puppet/set/smile", b",f", b"\x3f\x00\x00\x00"),
                     _osc_message(b"/puppet/trigger/wow", b",i", b"\0\0\0\1"),
                     _osc_message(b"/puppet/record/start", b",", b""),
                     _osc_message(b"/puppet/set", b",sf", b"smile\0\0\0\x3f\x00\x00\x00")]


@settings(max_examples=300 * SCALE, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
@given(datagram=st.one_of(st.binary(max_size=300), st.sampled_from(OSC_CONTROL_SEEDS).flatmap(
    lambda seed: st.integers(0, len(seed) - 1).flatmap(
        lambda at: st.integers(0, 255).map(lambda byte: seed[:at] + bytes([byte]) + seed[at + 1:])))))
def test_osc_control_messages(datagram):
    _bounded("osc control", lambda: [osccontrol.api_message(address, arguments)
                                     for address, arguments in parse_datagram(datagram)])


# -- take folders -----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def good_take(tmp_path_factory) -> Path:
    """A small imported take (20 frames, two channels): what the garbling starts from."""
    root = tmp_path_factory.mktemp("fuzz")
    csv = root / "face.csv"
    csv.write_text("Timecode,BlendShapeCount,JawOpen,MouthSmileLeft\n"
                   + "".join(f"00:00:00:{i:02d}.000,2,{i / 20:.2f},{(i % 5) / 5:.2f}\n" for i in range(20)))
    mapping = root / "small.yaml"  # two targets: the examples stay quick
    mapping.write_text("devices:\n  csv: {url: 'replay:///dev/null'}\nchannels:\n  csv.JawOpen: {smoothing: {type: one_euro, min_cutoff: 1.0, beta: 0.5}}\n"
                       "  csv.MouthSmileLeft: {dead_zone: 0.05}\ntargets:\n"
                       "  - {fap: open_jaw, source: csv.JawOpen, range: [0, 700]}\n"
                       "  - {fap: stretch_l_cornerlip, source: csv.MouthSmileLeft, range: [0, 200]}\n")
    return import_csv(csv, root / "takes", "good", fps=30, mapping_path=mapping)


@pytest.fixture(scope="module")
def shared(face):
    from puppet.runtime.runtime import Runtime

    return face, Runtime(face)


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=10),
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
                    max_leaves=12)
KEYS = ["name", "fps", "t0_ns", "hold_ns", "mapping", "mapping_text", "mapping_state", "devices", "wire",
        "layer", "frames", "samples", "complete"]


@st.composite
def damage(draw):
    """One garbling of a take folder: (file, how, argument)."""
    part = draw(st.sampled_from(["take.json", "samples.jsonl", "take.fap"]))
    how = draw(st.sampled_from(["key", "replace json", "bytes", "cut", "append line", "delete"]))
    if how == "key":
        return part, how, (draw(st.sampled_from(KEYS)), draw(JSON))
    if how == "replace json":
        return part, how, draw(JSON)
    if how == "bytes":
        return part, how, draw(st.binary(max_size=300))
    if how == "append line":
        return part, how, draw(st.sampled_from(['{"t_ns": 1, "device": "csv", "values": {"JawOpen": []}}',
                                                '{"t_ns": 1e400}', "[" * 5000, '{"event": "frame"}',
                                                '{"t_ns": 99999999999, "event": "hold", "states": 3}',
                                                '{"t_ns": 5, "device": "ghost", "values": {"x": 1}}'])
                                  | st.text(max_size=60))
    return part, how, draw(st.floats(0, 1))


def _spoil(folder: Path, part: str, how: str, arg) -> None:
    path = folder / part
    if how == "key" and part == "take.json":
        try:
            meta = json.loads(path.read_text())
        except ValueError:
            return  # spoilt already
        if isinstance(meta, dict):
            meta[arg[0]] = arg[1]
            path.write_text(json.dumps(meta))
    elif how == "replace json":
        path.write_text(json.dumps(arg))
    elif how == "bytes":
        path.write_bytes(arg)
    elif how == "cut":
        data = path.read_bytes()
        path.write_bytes(data[:int(len(data) * arg)])
    elif how == "append line":
        with open(path, "a", encoding="utf-8", errors="surrogatepass") as file:
            file.write(arg + "\n")
    elif how == "delete":
        path.unlink()


@settings(max_examples=40 * SCALE, deadline=10_000, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(spoilt=st.lists(damage(), min_size=1, max_size=2))
def test_garbled_take_folders(good_take, shared, spoilt):
    """Replay (``retake``) and play (``FapPlayback``, which render and export read a take through
    as well) a copy of a good take with one or two of its parts garbled."""
    face, runtime = shared
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch) / "take_001"
        shutil.copytree(good_take, folder)
        for part, how, arg in spoilt:
            if (folder / part).exists():
                _spoil(folder, part, how, arg)
        _bounded("take replay", lambda: retake(open_take(folder), Path(scratch) / "again.fap"))
        _bounded("take play", lambda: sum(1 for _ in FapPlayback(folder, face, runtime)))
