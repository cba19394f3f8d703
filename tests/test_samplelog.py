"""Raw sample logs round-trip exactly, survive a killed recorder, and replay as a device."""

from __future__ import annotations

import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from devices import open_device
from devices.base import Sample, State
from devices.replay_device import ReplayDevice
from devices.samplelines import read_samples
from puppet.io.samplelog import SampleLogWriter

values = st.dictionaries(st.text("abcxyz0123._", min_size=1, max_size=8),
                         st.floats(allow_nan=False, allow_infinity=False), max_size=6)
samples = st.lists(st.builds(Sample, st.integers(0, 2**62), st.sampled_from(["box", "pad"]), values), max_size=30)


@settings(max_examples=60, deadline=None)
@given(samples)
def test_a_log_reads_back_exactly(tmp_path_factory, recorded):
    path = tmp_path_factory.mktemp("log") / "take.samples.jsonl"
    with SampleLogWriter(path) as log:
        for sample in recorded:
            log.write(sample)
    assert list(read_samples(path)) == recorded


def test_a_recorder_killed_mid_line_leaves_every_complete_sample(tmp_path):
    path = tmp_path / "take.samples.jsonl"
    with SampleLogWriter(path) as log:
        for i in range(5):
            log.write(Sample(i, "box", {"ch0": float(i)}))
    with open(path, "a") as file:
        file.write('{"t_ns": 5, "device": "bo')
    with pytest.warns(UserWarning, match="last line is incomplete"):
        got = list(read_samples(path))
    assert [s.values["ch0"] for s in got] == [0, 1, 2, 3, 4]


def test_a_bad_line_in_the_middle_names_file_and_line(tmp_path):
    path = tmp_path / "bad.jsonl"
    path.write_text('{"t_ns": 1, "device": "box", "values": {"a": 1}}\nnot json\n{"t_ns": 2, "device": "box", "values": {}}\n')
    with pytest.raises(ValueError, match=r"bad.jsonl:2: expected a JSON sample"):
        list(read_samples(path))


def test_replay_keeps_the_spacing_and_the_values(tmp_path):
    """Replayed samples come on the log's schedule, each never early and late by at most a
    scheduler's hiccup, and one late sample does not push the later ones back (on a loaded
    machine a gap of 46 ms was followed by one of 34: back on time)."""
    path = tmp_path / "take.samples.jsonl"
    with SampleLogWriter(path) as log:
        for i in range(6):
            log.write(Sample(1_000_000_000 + i * 40_000_000, "box", {"ch0": float(i)}))
        log.write(Sample(2_000_000_000, "pad", {"X": 0.5}))
    device = open_device(f"replay://{path}?device=box", name="box")
    assert isinstance(device, ReplayDevice)
    with device:
        got = []
        for sample in device.samples(timeout=1.0):
            got.append(sample)
            if len(got) == 6:
                break
    assert [s.values["ch0"] for s in got] == [0, 1, 2, 3, 4, 5]
    offsets = [(sample.t_ns - got[0].t_ns) / 1e6 for sample in got]
    assert all(40 * i - 1 < offset < 40 * i + 25 for i, offset in enumerate(offsets)), offsets


def test_replay_as_fast_as_possible_and_a_missing_log_is_lost(tmp_path):
    path = tmp_path / "fast.jsonl"
    with SampleLogWriter(path) as log:
        for i in range(200):
            log.write(Sample(i * 10**9, "box", {"ch0": float(i)}))
    with ReplayDevice("box", path, speed=0) as device:
        start = time.monotonic()
        n = sum(1 for _ in zip(range(200), device.samples(timeout=1.0)))
        assert n == 200 and time.monotonic() - start < 2.0
    with ReplayDevice("box", tmp_path / "missing.jsonl") as device:
        assert device.wait_state(State.LOST, 1.0)
        assert "no such sample log" in device.counters.last_error


def test_a_line_longer_than_the_limit_is_refused_unread(tmp_path):
    from devices.samplelines import MAX_LINE, SampleLogError, read_samples

    log = tmp_path / "samples.jsonl"
    good = '{"t_ns": 1, "device": "box", "values": {"a": 1.0}}\n'
    log.write_text(good + '{"t_ns": 2, "device": "box", "values": {"a": ' + "1" * (2 * MAX_LINE) + "}}\n" + good)
    stream = read_samples(log)
    assert next(stream).values == {"a": 1.0}
    with pytest.raises(SampleLogError, match=r"samples.jsonl:2: a line of more than 1,048,576 characters"):
        next(stream)


def test_a_deeply_nested_line_is_a_sample_log_error(tmp_path):
    from devices.samplelines import SampleLogError, read_samples

    log = tmp_path / "samples.jsonl"
    log.write_text("[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(SampleLogError, match="samples.jsonl:1: expected a JSON sample"):
        list(read_samples(log))
