"""``puppet bench`` measures what it says on a real face (a few frames, as a smoke test)."""

import json

import numpy as np
import pytest

from puppet.bench.deform import bench_face, performance
from puppet.bench.run import SECTIONS, run_bench
from puppet.face.load import load_face


@pytest.mark.slow
def test_bench_face_reports_every_figure():
    row = bench_face(load_face(), frames=3)
    for key in ("rig_s", "precompute_s", "load_s", "deform_ms", "deform_normals_ms", "realtime_ms", "dense_ms", "ratio"):
        assert row[key] > 0, key
    assert row["vertices"] == len(load_face().vertices)
    assert row["deform_normals_ms"] >= row["deform_ms"] * 0.5


def test_the_benchmark_take_is_smooth():
    d, angles = performance(np.random.default_rng(0), 120, 5, 0.1)
    assert np.abs(d).max() <= 0.1
    assert np.abs(np.diff(d, axis=0)).max() < 0.1 * 2 * np.pi * 2.0 / 60 + 1e-12
    assert 0 <= angles.min() and angles.max() <= np.radians(15) + 1e-12


@pytest.mark.slow
def test_run_bench_prints_json(capsys, monkeypatch):
    monkeypatch.setattr("puppet.bench.run.bench_faces", lambda ict, subdivided=True: [(load_face(), None, "default")])
    monkeypatch.setattr("puppet.bench.run.bench_inputs", lambda seconds: [{"adapter": "x", "samples_s": 1.0}])
    everything_but_the_show = tuple(s for s in SECTIONS if s != "show")  # measured on its own below
    assert run_bench(frames=2, as_json=True, ict=False, flood_seconds=1.0, take_seconds=30.0,
                     only=everything_but_the_show) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["latency"]["samples"] > 0 and report["latency"]["sample_to_drawn_ms"]["median"] > 0 and report["long_take"]["frames"] == 30 * 30 + 1
    assert report["deform"][0]["face"] == "default"
    frame = report["frames"][0]
    assert frame["input"] == "FAP" and frame["fps"] > 0
    assert 0 < frame["deform_share"] < 1


@pytest.mark.slow
def test_every_adapter_carries_samples_through_its_mapping():
    from puppet.bench.inputs import bench_inputs

    rows = bench_inputs(seconds=0.3)
    assert [r.get("error") for r in rows] == [None] * len(rows)
    for row in rows:
        assert row["samples_s"] > 100 and row["paced_samples_s"] > 100, row["adapter"]
        assert row["bad_frames"] <= 2, row  # joining a stream mid-frame costs a frame per run, no more
        assert 0 < row["latency_median_ms"] <= row["latency_p99_ms"]


@pytest.mark.slow
def test_the_show_section_times_the_page_and_the_loop_with_and_without_clients(capsys):
    assert run_bench(as_json=True, only=("show",), quick=True) == 0
    show = json.loads(capsys.readouterr().out)["show"]
    feed, crowd = show["feed"], show["clients"]
    assert feed["feed_kb_s"] < feed["png_kb_s"] and feed["encode_ms"] < feed["png_encode_ms"]
    if "error" not in feed:
        assert feed["drawn"] > 0 and 0 < feed["delay_ms"]["median"] <= feed["delay_ms"]["p99"]
    assert all(crowd[k]["fps"] > 0 for k in ("no_clients", "four_clients", "no_clients_again"))
    assert crowd["api_answers_s"] > 0 and crowd["ratio"] > 0


def test_only_the_sections_asked_for_are_measured_with_progress_on_stderr(capsys):
    assert run_bench(frames=2, as_json=True, only=("long_take",), take_seconds=10.0) == 0
    out = capsys.readouterr()
    assert list(json.loads(out.out)) == ["long_take"]
    assert "bench 1/1: long_take" in out.err


def test_the_cli_refuses_an_unknown_section_in_one_line(capsys):
    from puppet.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(["bench", "--only", "latency,speed"])
    assert exit_.value.code == 2 and "expected some of deform" in capsys.readouterr().err


def test_the_cli_sections_are_the_bench_sections():
    from puppet.bench.run import SECTIONS
    from puppet.cli import BENCH_SECTIONS

    assert BENCH_SECTIONS == SECTIONS


@pytest.mark.slow
def test_the_rig_section_times_both_fold_searches_on_the_same_face():
    from puppet.bench.rigtime import bench_rig

    [row] = bench_rig(runs=1, ict=False)
    assert row["face"] == "default" and row["vertices"] > 0 and row["same"]
    assert row["before_s"] > row["after_s"] > 0 and row["total_s"] == row["rig_s"] + row["after_s"]
