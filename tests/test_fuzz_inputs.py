"""Fuzzing what users and other programs hand us: arbitrary bytes and near-valid .fap files, and
take folders with a part garbled. Only documented errors may come out (``PuppetError`` and its
subclasses; ``MappingError`` and ``DeviceError`` for a take's mapping and devices), each input in
bounded time (hypothesis's deadline) and bounded memory (tracemalloc's peak). Set
PUPPET_FUZZ_SCALE (default 1) to multiply the examples, for a longer run; ``-s`` prints the tally."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import tracemalloc
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from devices.base import DeviceError
from puppet.arkit import import_csv
from puppet.errors import PuppetError
from puppet.fapfile import read_fap, write_fap
from puppet.mapping import MappingError
from puppet.playback import FapPlayback
from puppet.replay import retake
from puppet.takes import open_take

DOCUMENTED = (PuppetError, MappingError, DeviceError)
MEMORY_BOUND = 32_000_000
SCALE = int(os.environ.get("PUPPET_FUZZ_SCALE", "1"))
TALLY: Counter = Counter()


@pytest.fixture(scope="module", autouse=True)
def report():
    yield
    print("\nfuzz tally:", dict(sorted(TALLY.items())))


def _bounded(kind: str, action) -> object:
    """Run ``action``; count what came out; fail on anything undocumented or a memory peak past
    the bound."""
    tracemalloc.start()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = action()
        TALLY[f"{kind}: read"] += 1
    except DOCUMENTED:
        TALLY[f"{kind}: documented error"] += 1
        result = None
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
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


# -- take folders -----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def good_take(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("fuzz")
    csv = root / "face.csv"
    csv.write_text("Timecode,BlendShapeCount,JawOpen,MouthSmileLeft\n"
                   + "".join(f"00:00:00:{i:02d}.000,2,{i / 20:.2f},{(i % 5) / 5:.2f}\n" for i in range(20)))
    mapping = root / "small.yaml"  # the shipped ARKit mapping takes a second to parse: keep examples quick
    mapping.write_text("devices:\n  csv: {url: 'replay:///dev/null'}\nchannels:\n  csv.JawOpen: {smoothing: {type: one_euro, min_cutoff: 1.0, beta: 0.5}}\n"
                       "  csv.MouthSmileLeft: {dead_zone: 0.05}\ntargets:\n"
                       "  - {fap: open_jaw, source: csv.JawOpen, range: [0, 700]}\n"
                       "  - {fap: stretch_l_cornerlip, source: csv.MouthSmileLeft, range: [0, 200]}\n")
    return import_csv(csv, root / "takes", "good", fps=30, mapping_path=mapping)


@pytest.fixture(scope="module")
def shared(face):
    from puppet.runtime import Runtime

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
    face, runtime = shared
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch) / "take_001"
        shutil.copytree(good_take, folder)
        for part, how, arg in spoilt:
            if (folder / part).exists():
                _spoil(folder, part, how, arg)
        _bounded("take replay", lambda: retake(open_take(folder), Path(scratch) / "again.fap"))
        _bounded("take play", lambda: sum(1 for _ in FapPlayback(folder, face, runtime)))
