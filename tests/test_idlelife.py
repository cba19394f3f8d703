"""Idle life: the face blinks at a person's resting rate and shape, its eyes wander a little and it
breathes, the same for the same seed however it is sampled, yields at once to a channel on the
same FAPs, is off with ``idle: false``, and a take with it rebuilds to the identical .fap."""

from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from devices import State, open_device
from devices.base import Sample
from puppet import MappingError
from puppet.fap.pose import Pose
from puppet.io.takes import open_take
from puppet.live.idlelife import LID_LOWER, LID_UPPER, PART_FAPS, IdleLife
from puppet.live.mappingfile import parse_mapping
from puppet.live.retake import retake
from puppet.live.session import LiveSession

S = 1_000_000_000
FPS = 30
JOYSTICK = "sim://joystick?protocol=ascii&rate=200&channels=6"
BLINK = [n - 1 for n in PART_FAPS["blink"]]
EYES = [n - 1 for n in PART_FAPS["eyes"]]
BREATH = [n - 1 for n in PART_FAPS["breath"]]


def mapping_text(idle: str = "", targets: str = "") -> str:
    return f"""
devices:
  box: {{url: "{JOYSTICK}"}}
channels:
  box.ch0: {{min: 0, max: 1023}}
  box.ch1: {{min: 0, max: 1023}}
targets:
  - {{fap: open_jaw, source: box.ch0, range: [0, 600]}}
{targets}
{idle}
"""


def frames(life: IdleLife, seconds: float, fps: int = FPS) -> tuple[np.ndarray, np.ndarray]:
    t = life.origin_ns + np.arange(int(seconds * fps)) * (S // fps)
    return t, life.offsets(t)


def blink_onsets(lid: np.ndarray) -> np.ndarray:
    """Frames where the upper lid starts to move after resting open."""
    moving = lid > 1.0
    return np.flatnonzero(moving[1:] & ~moving[:-1]) + 1


def blink_peak(life: IdleLife) -> int:
    """A time (ns) when the first blink is shut."""
    t = life.origin_ns + np.arange(0, 20 * S, S // 1000)
    lid = life.lids((t - life.origin_ns) / 1e9)
    return int(t[np.argmax(lid)])


# -- blinks -------------------------------------------------------------------------------------

@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1))
def test_the_blink_rate_over_ten_minutes_is_a_resting_person_s(seed):
    """About 17 a minute at rest (Bentivoglio et al. 1997), irregular, never two at once."""
    life = IdleLife(seed, 5 * S)
    _, out = frames(life, 600)
    onsets = blink_onsets(out[:, 18])
    rate = len(onsets) / 10
    assert 13 <= rate <= 21, rate
    gaps = np.diff(onsets) / FPS
    assert gaps.min() >= 0.5 and gaps.std() / gaps.mean() > 0.3   # irregular, not periodic


def test_a_blink_closes_fast_opens_slowly_and_the_upper_lid_does_the_moving():
    life = IdleLife(3, 0)
    t = np.arange(0, 30 * S, S // 1000)  # every millisecond
    out = life.offsets(t)
    upper, lower = out[:, 18], out[:, 20]
    assert upper.max() == pytest.approx(LID_UPPER) and lower.max() == pytest.approx(LID_LOWER)
    assert np.array_equal(out[:, 18], out[:, 19]) and np.array_equal(out[:, 20], out[:, 21])  # both eyes
    moving = upper > 0.0
    starts = np.flatnonzero(moving[1:] & ~moving[:-1]) + 1
    ends = np.flatnonzero(moving[:-1] & ~moving[1:]) + 1
    ends = ends[ends > starts[0]]
    assert len(starts) >= 4
    for a, b in zip(starts, ends):
        lid = upper[a:b]
        shut = np.flatnonzero(lid >= LID_UPPER * 0.999)
        closing, opening = shut[0], len(lid) - shut[-1]
        assert 2.0 <= opening / closing <= 3.2, (closing, opening)    # 1:2 to 1:3
        assert 250 <= len(lid) <= 520                                 # a few hundred ms


# -- eyes and breath ----------------------------------------------------------------------------

def test_the_eyes_make_small_saccades_together_and_the_breath_is_slow_and_small():
    life = IdleLife(11, 0)
    _, out = frames(life, 120, fps=200)
    yaw_deg = out[:, 22] * 1e-5 * 180 / np.pi
    pitch_deg = out[:, 24] * 1e-5 * 180 / np.pi
    assert np.array_equal(out[:, 22], out[:, 23]) and np.array_equal(out[:, 24], out[:, 25])
    assert np.abs(yaw_deg).max() < 0.7 and np.abs(pitch_deg).max() < 0.7
    speed = np.hypot(np.diff(yaw_deg), np.diff(pitch_deg)) * 200          # degrees a second
    jumps = np.flatnonzero(speed > 5.0)
    saccades = 1 + np.count_nonzero(np.diff(jumps) > 1)
    assert 120 / 3.2 <= saccades <= 120 / 0.9, saccades                   # one every 1-3 s
    shut = out[:, 18] >= 0.99 * LID_UPPER
    starts = jumps[np.r_[True, np.diff(jumps) > 1]]
    assert shut[starts].mean() > 5 * shut.mean()                          # gaze shifts come with blinks
    pitch = out[:, 47]
    inhale = np.flatnonzero((pitch[1:] < pitch.min() * 0.5) & (pitch[:-1] >= pitch.min() * 0.5))
    per_min = len(inhale) / 2
    assert 11 <= per_min <= 17, per_min                                   # 12-16 a minute
    assert -pitch.min() * 1e-5 * 180 / np.pi == pytest.approx(0.25, rel=0.01)


# -- determinism --------------------------------------------------------------------------------

@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 63 - 1), origin=st.integers(0, 2 ** 50),
       offsets=st.lists(st.integers(-5 * S, 900 * S), min_size=1, max_size=40), data=st.data())
def test_the_same_seed_gives_the_same_faps_in_any_order(seed, origin, offsets, data):
    times = [origin + o for o in offsets]
    shuffled = data.draw(st.permutations(times))
    first, second = IdleLife(seed, origin), IdleLife(seed, origin)
    a = {}
    for t in times:
        a[t] = np.zeros(68)
        first.add_to(a[t], t)
    for t in shuffled:
        b = np.zeros(68)
        second.add_to(b, t)
        assert np.array_equal(a[t], b)
    np.testing.assert_allclose(IdleLife(seed, origin).offsets(shuffled), np.array([a[t] for t in shuffled]),
                               rtol=0, atol=1e-9)
    before = [t for t in times if t < origin]
    assert not IdleLife(seed, origin).offsets(before).any() if before else True


def test_threads_asking_at_once_see_the_same_motion():
    """The session's loop and a control API's thread may both ask for a pose while the schedule grows."""
    import threading

    times = [k * 997_000_000 for k in range(7200)]           # two hours, drawn on as they go
    reference = IdleLife(17, 0).offsets(times)
    shared = IdleLife(17, 0)
    results = [np.full((len(times), 68), np.nan) for _ in range(4)]

    def ask(out, order):
        for k in order:
            out[k] = 0.0
            shared.add_to(out[k], times[k])

    rng = np.random.default_rng(0)
    threads = [threading.Thread(target=ask, args=(out, rng.permutation(len(times)))) for out in results]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for out in results:
        np.testing.assert_allclose(out, reference, rtol=0, atol=1e-9)
    assert all(np.array_equal(out, results[0]) for out in results)


def test_another_seed_gives_other_motion():
    a, b = IdleLife(1, 0), IdleLife(2, 0)
    assert not np.array_equal(frames(a, 30)[1], frames(b, 30)[1])


# -- in a mapping -------------------------------------------------------------------------------

def test_a_channel_on_the_lids_takes_them_at_once_and_idle_comes_back_when_it_rests():
    targets = "  - {fap: close_t_l_eyelid, source: box.ch1, range: [0, 500]}"
    m = parse_mapping(mapping_text("idle: {seed: 4}", targets), "m.yaml")
    m.idle = IdleLife(4, 0, m.idle.parts)
    peak = blink_peak(m.idle)
    alone = m.idle.offsets(peak)[0]
    assert alone[18] == pytest.approx(LID_UPPER)
    m.feed(Sample(peak - 1, "box", {"ch1": 512}))
    pose = m.pose(peak)
    assert pose.fap[18] == pytest.approx(500 * 512 / 1023)      # the channel's value alone, that frame
    assert not pose.fap[19:22].any()                            # the whole blink yields, not one lid
    np.testing.assert_array_equal(pose.fap[EYES], alone[EYES])  # the eyes are not driven: they go on
    np.testing.assert_array_equal(pose.fap[BREATH], alone[BREATH])
    assert m.idle_yields() == ("blink",)
    m.feed(Sample(peak, "box", {"ch1": 0}))
    np.testing.assert_array_equal(m.pose(peak).fap[BLINK], alone[BLINK])   # at rest again: blinks again


@pytest.mark.parametrize("target, parts", [
    ("  - {eyes: yaw, source: box.ch1, range: [-20, 20]}", ("eyes",)),
    ("  - {head: pitch, source: box.ch1, range: [0, 10]}", ("breath",)),
    ("  - {expression: disgust, source: box.ch1}", ("blink", "breath")),  # lids, nostrils (nose wrinkler)
    ("  - {muscle: orbicularis_oculi_r, source: box.ch1}", ("blink",)),
    ("  - {fap: stretch_l_nose, source: box.ch1, range: [0, 100]}", ("breath",)),
])
def test_each_part_yields_to_whatever_writes_its_faps(target, parts):
    m = parse_mapping(mapping_text("", target), "m.yaml")
    m.idle = IdleLife(9, 0)
    m.pose(S)
    assert m.idle_yields() == ()
    m.feed(Sample(S, "box", {"ch1": 1023}))
    m.pose(S)
    assert m.idle_yields() == parts


@pytest.mark.parametrize("trigger, parts", [
    ("{mode: hold, faps: {close_t_l_eyelid: 600}, attack: 0.1, release: 0.2}", ("blink",)),
    ("{mode: hold, expression: disgust, attack: 0.1, release: 0.2}", ("blink", "breath")),  # lids, nostrils
    ("{mode: hold, faps: {yaw_l_eyeball: 20000}, attack: 0.1, release: 0.2}", ("eyes",)),
    ("{mode: hold, faps: {head_pitch: 3000}, attack: 0.1, release: 0.2}", ("breath",)),
])
def test_a_trigger_that_moves_a_part_s_faps_takes_them_while_it_plays(trigger, parts):
    m = parse_mapping(mapping_text("", f"triggers:\n  it: {trigger}"), "m.yaml")
    m.idle = IdleLife(9, 0)
    m.pose(S)
    assert m.idle_yields() == ()
    m.trigger("it", "press", S)
    m.pose(S + S // 100)                 # 10 ms into the attack: already the trigger's
    assert m.idle_yields() == parts
    m.trigger("it", "release", 2 * S)
    m.pose(2 * S + S // 10)              # still falling
    assert m.idle_yields() == parts
    m.pose(3 * S)                        # at rest: idle life again
    assert m.idle_yields() == ()


def test_a_held_pose_holds_the_channels_while_idle_life_goes_on():
    m = parse_mapping(mapping_text(), "m.yaml")
    m.idle = IdleLife(5, 0)
    m.feed(Sample(S, "box", {"ch0": 700}))
    poses = [m.pose(S, S + k * S // 10) for k in range(30)]
    assert len({p.fap[2] for p in poses}) == 1                  # the jaw holds
    assert len({p.fap[22] for p in poses}) > 1                  # the eyes drift on


def test_idle_false_keeps_the_face_still_and_idle_parts_can_be_switched_off():
    still = parse_mapping(mapping_text("idle: false"), "m.yaml")
    assert still.idle is None and still.snapshot()["idle"] is None
    assert not any(still.pose(t).fap.any() for t in range(0, 600 * S, S // 7))
    some = parse_mapping(mapping_text("idle: {blink: false, breath: false, seed: 12}"), "m.yaml")
    assert some.idle.parts == ("eyes",) and some.idle.seed == 12
    assert some.idle.describe().startswith("idle life: eyes (seed 12;")   # what puppet live says at start
    on = parse_mapping(mapping_text(), "m.yaml")
    assert on.idle.parts == ("blink", "eyes", "breath")
    assert on.idle.origin_ns <= time.monotonic_ns()
    assert on.snapshot()["idle"] == {"seed": on.idle.seed, "origin_ns": on.idle.origin_ns,
                                     "parts": ["blink", "eyes", "breath"]}


def test_a_replay_takes_the_recorded_seed_and_origin_and_an_older_take_gets_no_idle_life():
    recorded = parse_mapping(mapping_text("idle: {seed: 3}"), "m.yaml")
    state = recorded.snapshot()
    other = parse_mapping(mapping_text("idle: {seed: 99, breath: false}"), "other.yaml")
    other.restore(state, recorded)
    assert (other.idle.seed, other.idle.origin_ns, other.idle.parts) == (3, recorded.idle.origin_ns, ("blink", "eyes"))
    del state["idle"]                                  # a take made before idle life
    other.restore(state, recorded)
    assert other.idle is None and not other.pose(recorded.idle.origin_ns + 100 * S).fap.any()
    other.restore(recorded.snapshot(), recorded)
    assert other.idle.seed == 3


@pytest.mark.parametrize("idle, message", [
    ("idle: maybe", "m.yaml:.*idle: expected true, false or a mapping"),
    ("idle: {blnk: false}", "unknown key 'blnk' in idle life.*did you mean 'blink'"),
    ("idle: {eyes: 1}", r"idle\.eyes: expected true or false, got 1"),
    ("idle: {seed: -3}", r"idle\.seed: expected a whole number from 0"),
    ("idle: {seed: 1.5}", r"idle\.seed: expected a whole number from 0"),
    ("idl: false", "unknown key 'idl'.*did you mean 'idle'"),
])
def test_a_bad_idle_key_is_one_clear_error(idle, message):
    with pytest.raises(MappingError, match=message):
        parse_mapping(mapping_text(idle), "m.yaml")


# -- takes --------------------------------------------------------------------------------------

def test_a_take_with_idle_life_rebuilds_to_the_identical_fap(face, tmp_path):
    """The take records the blinks as FAPs and keeps the seed and origin; its log replayed through
    the mapping and through the serial adapter gives the same .fap, byte for byte."""
    from puppet.runtime.runtime import Runtime

    mapping = tmp_path / "idle.yaml"
    mapping.write_text(mapping_text("idle: {seed: 21}"))
    with LiveSession(mapping, face=Runtime(face), devices={"box": open_device(JOYSTICK, "box")},
                     record_root=tmp_path, fps=FPS) as session:
        deadline = time.monotonic() + 5
        while not (session.frame().states["box"] is State.OPEN and session.samples_fed):
            assert time.monotonic() < deadline
            time.sleep(0.01)
        life = session.mapping.idle
        peak = blink_peak(life)
        now = time.monotonic_ns()
        session.mapping.idle = IdleLife(life.seed, life.origin_ns - (peak - now) + S // 5, life.parts)  # blink soon
        session.start_recording()
        end = time.monotonic() + 0.8
        while time.monotonic() < end:
            session.frame()
            time.sleep(0.01)
        folder = session.stop_recording()
    take = open_take(folder)
    assert take.meta["mapping_state"]["idle"]["seed"] == 21
    values = take.stream().values
    assert values[:, 18].max() > 0.9 * LID_UPPER and np.ptp(values[:, 22]) > 0   # a blink, and the eyes
    assert retake(take, tmp_path / "again.fap").identical
    assert retake(take, tmp_path / "wire.fap", through_devices=True).identical


def test_an_unplugged_device_holds_the_performed_jaw_while_the_face_goes_on_living(face, tmp_path):
    from puppet.runtime.runtime import Runtime

    mapping = tmp_path / "idle.yaml"
    mapping.write_text(mapping_text())
    with LiveSession(mapping, face=Runtime(face), devices={"box": open_device(JOYSTICK, "box")},
                     record_root=tmp_path, fps=FPS) as session:
        deadline = time.monotonic() + 5
        while not (session.frame().states["box"] is State.OPEN and session.samples_fed > 20):
            assert time.monotonic() < deadline
            time.sleep(0.01)
        box = session.devices["box"]
        box.joystick.unplug()
        assert box.wait_state(State.LOST, 5.0)
        session.frame()
        held = []
        for _ in range(8):
            time.sleep(0.03)
            f = session.frame()
            assert f.states["box"] in (State.LOST, State.OPENING) and f.n_samples == 0
            held.append((f.pose.fap.copy(), f.vertices.copy()))
    jaws = {fap[2] for fap, _ in held}
    assert len(jaws) == 1                                               # the performed jaw holds
    assert len({fap[22] for fap, _ in held}) == len(held)               # the eyes drift on
    assert not np.array_equal(held[0][1], held[-1][1])                  # and the face shows it


# -- what it looks like -------------------------------------------------------------------------

def test_a_blink_peak_shuts_the_eyes_and_leaves_the_mouth(face, runtime, egl, tmp_path):
    from PIL import Image

    from puppet.view.renderer import Renderer

    life = IdleLife(8, 0, ("blink",))
    peak = life.offsets(blink_peak(life))[0]
    rest, _ = runtime.deform_pose(Pose(np.zeros(68)))
    shut, _ = runtime.deform_pose(Pose(peak))
    with Renderer.for_face(face, width=400, height=400) as r:
        r.aim(face.vertices)
        a = r.render(rest.astype(np.float32)).astype(int)
        b = r.render(shut.astype(np.float32)).astype(int)
        fp = face.feature_points
        eye, mouth = r.project(np.array([fp["3.1"], (fp["8.1"] + fp["8.2"]) / 2])).astype(int)
    Image.fromarray(np.concatenate([a, b], axis=1).astype(np.uint8)).save(tmp_path / "blink.png")
    diff = np.abs(a - b).sum(axis=2)
    around_eye = diff[eye[1] - 12:eye[1] + 12, eye[0] - 20:eye[0] + 20]
    around_mouth = diff[mouth[1] - 15:mouth[1] + 15, mouth[0] - 30:mouth[0] + 30]
    assert (around_eye > 60).mean() > 0.2            # the lid covers the eye
    assert around_mouth.max() <= 3                   # the mouth does not move
