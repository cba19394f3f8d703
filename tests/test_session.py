"""The live session: a simulated serial slider box drives the face, holds it when unplugged,
records a take at its frame rate, and can be timed from input to drawn frame."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

from devices import State, open_device
from puppet.io.takes import open_take
from puppet.live.session import LiveSession, measure_latency
from puppet.runtime.runtime import Runtime

MAPPING = Path(__file__).resolve().parents[1] / "mappings" / "arduino_sliders.yaml"
JOYSTICK = "sim://joystick?protocol=ascii&rate=200&channels=6"


@pytest.fixture(scope="module")
def shared_runtime(face):
    return Runtime(face)


@pytest.fixture
def session(shared_runtime, tmp_path):
    s = LiveSession(MAPPING, face=shared_runtime, devices={"box": open_device(JOYSTICK, "box")},
                    record_root=tmp_path, fps=30)
    yield s
    s.close()


def _run_until(session, condition, timeout=5.0, period=0.005):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        f = session.frame()
        if condition(f):
            return f
        time.sleep(period)
    pytest.fail("timed out")


def test_sliders_move_the_face_and_an_unplugged_box_holds_it(session, shared_runtime):
    session.mapping.idle = None   # idle life goes on through a hold (tests/test_idlelife.py); here: the channels
    box = session.devices["box"]
    rest = shared_runtime.rest
    f = _run_until(session, lambda f: f.states["box"] is State.OPEN and f.newest_sample_ns is not None
                   and not np.allclose(f.vertices, rest))
    assert f.vertices.shape == rest.shape and np.isfinite(f.normals).all()

    box.joystick.unplug()
    assert box.wait_state(State.LOST, 5.0)
    held = session.frame()                       # takes in what came before the plug was pulled
    held_vertices, held_fap = held.vertices.copy(), held.pose.fap.copy()
    for _ in range(10):
        time.sleep(0.02)
        f = session.frame()
        assert f.states["box"] in (State.LOST, State.OPENING)
        assert f.n_samples == 0
        np.testing.assert_array_equal(f.vertices, held_vertices)
        np.testing.assert_array_equal(f.pose.fap, held_fap)

    box.joystick.replug()
    assert box.wait_state(State.OPEN, 5.0)
    _run_until(session, lambda f: f.states["box"] is State.OPEN and f.n_samples > 0
               and not np.allclose(f.vertices, held_vertices, atol=1e-6))


def test_a_take_has_fps_frames_per_second_and_every_sample(session):
    _run_until(session, lambda f: f.states["box"] is State.OPEN and f.n_samples > 0)
    session.start_recording()
    first = last = None
    fed = 0
    while first is None or last - first < 1_000_000_000:
        f = session.frame()
        fed += f.n_samples
        if f.n_samples:
            first = first if first is not None else f.newest_sample_ns
            last = f.newest_sample_ns
        time.sleep(0.01)
    folder = session.stop_recording()
    take = open_take(folder)
    frames = len(take.stream())
    samples = list(take.samples())
    assert abs(frames - 30) <= 2, frames
    assert len(samples) == fed and fed >= 150      # 200 readings/s for ~1 s, every one logged
    assert take.meta["frames"] == frames and take.meta["samples"] == fed


def test_a_slow_loop_still_writes_every_tick(session):
    """Frames are written per tick of take time, not per loop turn."""
    _run_until(session, lambda f: f.states["box"] is State.OPEN and f.n_samples > 0)
    t0 = time.monotonic_ns()
    session.start_recording(t0)
    session.frame(t0 + 10 * 1_000_000_000 // 30)    # one late frame covers ticks 0..10
    folder = session.stop_recording()
    assert len(open_take(folder).stream()) == 11


def test_measure_latency_offscreen_counts_every_sample(session, face, egl):
    from puppet.view.renderer import Renderer

    renderer = Renderer(face.triangles, len(face.vertices), face.colors, width=320, height=240)
    try:
        _run_until(session, lambda f: f.states["box"] is State.OPEN and f.n_samples > 0)
        fed = session.samples_fed
        result = measure_latency(session, renderer, 0.7)
    finally:
        renderer.release()
    assert result["samples"] > 0  # every sample, not one a frame; those queued before the loop apart
    assert result["samples"] + result["samples_before"] == session.samples_fed - fed
    drawn, mesh = result["sample_to_drawn_ms"], result["sample_to_mesh_ms"]
    assert 0 < drawn["median"] <= drawn["p99"] and 0 < mesh["median"] <= mesh["p99"]
    assert mesh["median"] <= drawn["median"] and 0 < result["frame_work_ms"]["median"] <= mesh["median"]
    assert result["normals"] == "cpu" and session.normals  # this GL draws on the CPU: normals from the runtime
    assert result["gl_renderer"]
    if len(os.sched_getaffinity(0)) >= 2 and "LP_NUM_THREADS" not in os.environ:  # llvmpipe: a thread a core
        assert len(result["rasteriser_cores"]) >= 2  # ... each on a core of its own


# -- faults ------------------------------------------------------------------------------------

def test_a_device_that_never_answers_leaves_the_face_at_rest_and_the_take_valid(shared_runtime, tmp_path):
    from devices.simulated_serial import PtyJoystick

    with PtyJoystick(rate=None) as silent:  # a port that opens and then says nothing
        box = open_device(f"serial://{silent.path}?protocol=ascii", "box")
        with LiveSession(MAPPING, face=shared_runtime, devices={"box": box}, record_root=tmp_path) as s:
            s.mapping.idle = None   # rest is the channels' rest; idle life would blink on (tests/test_idlelife.py)
            assert box.wait_state(State.OPEN, 5.0)
            s.start_recording()
            for _ in range(5):
                f = s.frame()
                time.sleep(0.02)
            np.testing.assert_allclose(f.vertices, shared_runtime.rest, atol=1e-6)
            assert f.newest_sample_ns is None and f.states["box"] is State.OPEN
            take = open_take(s.stop_recording())
    assert len(take.stream()) >= 2 and not take.stream().values[:, 2:].any()


def test_a_mapping_that_names_a_missing_device_fails_before_anything_opens(shared_runtime, tmp_path):
    import threading

    from puppet import MappingError

    broken = tmp_path / "broken.yaml"
    broken.write_text(MAPPING.read_text().replace("source: box.ch0", "source: boxx.ch0"))
    threads = threading.active_count()
    with pytest.raises(MappingError, match="device 'boxx', which is not defined"):
        LiveSession(broken, face=shared_runtime, record_root=tmp_path)
    assert threading.active_count() == threads     # no device thread was started
    assert list(tmp_path.iterdir()) == [broken]     # and no take folder made


def test_a_mapping_that_would_make_nan_is_refused_before_anything_opens(shared_runtime, tmp_path):
    """Issue 12: one_euro min_cutoff 1e308 loaded, its NaN pose raised out of frame() at the first
    recorded frame and the take was marked complete with 0 frames."""
    from puppet import MappingError

    huge = tmp_path / "huge.yaml"
    huge.write_text(MAPPING.read_text().replace("min_cutoff: 1.0,", "min_cutoff: 1.0e+308,", 1))
    with pytest.raises(MappingError, match=r'huge.yaml:\d+: channels\["box.ch0"\]\.smoothing\.min_cutoff: '
                                           r"expected a frequency in Hz > 0 and <= 1000, got 1e\+308"):
        LiveSession(huge, face=shared_runtime, record_root=tmp_path)


def test_a_nan_in_the_mapping_holds_the_last_good_pose_and_is_reported_once(session):
    _run_until(session, lambda f: f.states["box"] is State.OPEN and f.n_samples > 0)
    state = session.mapping.snapshot()
    jaw = state["channels"]["box.ch0"]
    jaw["value"] = jaw["out"] = float("nan")
    jaw["smoother"][1] = [float("nan"), 0.0]        # a corrupt state: the filter stays NaN
    good = session.frame().pose.fap.copy()
    session.mapping.restore(state)
    session.start_recording()
    with pytest.warns(RuntimeWarning) as caught:
        for _ in range(20):
            f = session.frame()
            time.sleep(0.005)
    assert len(caught) == 1 and "fap 3 open_jaw came out as NaN" in str(caught[0].message)
    assert session.pose_error == str(caught[0].message) and session.mapping.held_values >= 20
    assert np.isfinite(f.pose.fap).all() and f.pose.fap[2] == good[2]
    assert np.isfinite(f.vertices).all()
    take = open_take(session.stop_recording())
    assert take.meta["complete"] and len(take.stream()) >= 1
    assert np.isfinite(take.stream().values).all()


def test_a_take_whose_write_fails_is_never_marked_complete_and_the_face_goes_on(session, monkeypatch):
    _run_until(session, lambda f: f.states["box"] is State.OPEN and f.n_samples > 0)
    folder = session.start_recording()

    def broken(*args, **kwargs):
        raise ValueError("FAP 3: expected a finite value, found nan")

    monkeypatch.setattr(session._clock, "write", broken)   # the take's .fap writer refuses a frame
    for _ in range(10):
        f = session.frame()
        time.sleep(0.01)
    assert not session.recording and "recording stopped after 0 frames: ValueError" in session.record_error
    assert f.n_samples >= 0 and np.isfinite(f.vertices).all()
    session.close()
    meta = open_take(folder).meta
    assert meta["complete"] is False and "ValueError" in meta["error"]


def test_a_loop_waiting_for_input_wakes_with_a_sample_and_not_without(session):
    """``wait_for_input`` returns as soon as a Sample is queued (the loop then shows it at once),
    and waits its time out while the box sends nothing."""
    box = session.devices["box"]
    assert box.wait_state(State.OPEN, 5.0)
    assert session.wait_for_input(5.0)
    assert session.frame().n_samples > 0
    box.joystick.unplug()
    assert box.wait_state(State.LOST, 5.0)
    session.frame()                                # drains what came before the plug was pulled
    assert not session.wait_for_input(0.05)
    assert session.frame().n_samples == 0
