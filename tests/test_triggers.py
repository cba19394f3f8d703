"""Triggers: poses held, latched or played once on a key, a note or a call by name; their
envelopes, a clip of a take, the live window's keys, a take rebuilt exactly, the checks."""

from __future__ import annotations

import itertools
import json
import re
import time
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from window_keys import WindowKeys as _Keys

from devices import open_device
from devices.base import Sample
from devices.keys_device import KEY_NAMES, WINDOW_KEYS, KeysDevice
from puppet.io.fapfile import FapWriter, read_fap
from puppet.io.samplelog import LogEvent
from puppet.io.takes import open_take, write_pose
from puppet.live.idlelife import PART_FAPS
from puppet.live.mappingfile import MappingError, compile_mapping, parse_mapping
from puppet.live.retake import retake
from puppet.live.session import LiveSession
from puppet.live.takeclock import TakeClock
from puppet.live.triggercheck import CLIP_KEYS, TRIGGER_KEYS
from puppet.live.triggers import EASES, MODES, Trigger, TriggerSpec
from puppet.runtime.runtime import Runtime
from puppet.view.livewindow import LiveView, open_session, trigger_keys
from puppet.view.overlay import KEYS

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = json.loads((ROOT / "mappings" / "schema.json").read_text())
VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)
S = 1_000_000_000
JOY = 1


def doc(**triggers) -> dict:
    """A keys mapping (keys 1-3, a jaw target on 9) with these triggers."""
    return {"devices": {"keys": {"url": "keys://"}},
            "channels": {"keys.1": None, "keys.2": None, "keys.3": None, "keys.9": None},
            "targets": [{"fap": "open_jaw", "source": "keys.9", "range": [0, 300]}],
            "triggers": triggers}


def key(mapping, name: str, down: bool, t_ns: int) -> None:
    mapping.feed(Sample(t_ns, "keys", {name: 1.0 if down else 0.0}))


def joy(mapping, t_ns: int) -> float:
    """The intensity of joy in the pose at ``t_ns`` (0 when joy is not the strongest)."""
    expression = mapping.pose(t_ns).expression
    return expression[1] if expression[0] == JOY else 0.0


# -- envelopes ---------------------------------------------------------------------------------

def test_hold_rises_over_its_attack_and_falls_over_its_release():
    m = compile_mapping(doc(smile={"source": "keys.1", "mode": "hold", "expression": "joy", "attack": 0.2,
                                   "release": 0.4, "ease": "linear"}))
    assert m.pose(0).expression == (0, 0.0, 0, 0.0)
    key(m, "1", True, 10 * S)
    assert [joy(m, 10 * S + k * S // 10) for k in range(4)] == pytest.approx([0.0, 31.5, 63.0, 63.0])
    key(m, "1", False, 12 * S)
    assert [joy(m, 12 * S + k * S // 10) for k in (0, 2, 4, 6)] == pytest.approx([63.0, 31.5, 0.0, 0.0])
    key(m, "1", True, 20 * S)          # let go half way up: it falls from there, never jumps
    key(m, "1", False, 20 * S + S // 10)
    assert joy(m, 20 * S + S // 10) == pytest.approx(31.5)
    assert joy(m, 20 * S + 2 * S // 10) == pytest.approx(15.75)
    assert joy(m, 21 * S) == 0.0


def test_the_smooth_ease_starts_and_ends_gently():
    m = compile_mapping(doc(smile={"source": "keys.1", "mode": "hold", "expression": "joy", "attack": 0.4}))
    key(m, "1", True, S)
    rise = [joy(m, S + k * S // 100) for k in range(41)]
    steps = np.diff(rise)
    assert rise[20] == pytest.approx(31.5) and rise[-1] == 63.0
    assert steps[0] < steps[20] / 10 and steps[-1] < steps[20] / 10   # slow, fast, slow


def test_toggle_latches_on_and_off_and_a_release_does_nothing():
    m = compile_mapping(doc(grin={"source": "keys.2", "mode": "toggle", "faps": {"open_jaw": 300, 12: 150},
                                  "attack": 0.1, "release": 0.1}))
    key(m, "2", True, S)
    key(m, "2", False, S + S // 20)
    on = m.pose(2 * S).fap
    assert on[2] == 300 and on[11] == 150 and m.trigger_states(2 * S)[0].latched
    key(m, "2", True, 3 * S)
    key(m, "2", False, 3 * S + S // 20)
    assert not m.pose(4 * S).fap.any() and not m.trigger_states(4 * S)[0].active
    m.trigger("grin", "fire", 5 * S)   # by name: a toggle flips
    assert m.pose(6 * S).fap[2] == 300


def test_a_oneshot_plays_attack_hold_release_and_ends_at_rest():
    m = compile_mapping(doc(wow={"source": "keys.3", "mode": "oneshot", "expression": "surprise", "attack": 0.1,
                                 "hold": 0.5, "release": 0.4, "ease": "linear", "strength": 0.5}))
    key(m, "3", True, S)
    key(m, "3", False, S + S // 100)   # a tap: the oneshot plays on
    level = [m.pose(S + k * S // 20).expression for k in range(25)]
    assert [e[1] for e in level[:3]] == pytest.approx([0.0, 15.75, 31.5])
    assert all(e == (6, 31.5, 0, 0.0) for e in level[2:13])      # 0.1 s .. 0.6 s: full (strength 0.5)
    assert level[16][1] == pytest.approx(31.5 * (1 - 0.2 / 0.4))
    assert m.pose(S + S).expression == (0, 0.0, 0, 0.0) and not m.pose(S + S).fap.any()
    assert m.trigger_states(2 * S)[0].level == 0.0


def test_fire_on_a_hold_trigger_is_a_press_and_a_release_at_once():
    m = compile_mapping(doc(smile={"mode": "hold", "expression": "joy"}))
    m.trigger("smile", "fire", S)
    assert joy(m, S + S // 10) == 0.0
    m.trigger("smile", "press", 2 * S)
    assert joy(m, 3 * S) == 63.0
    m.trigger("smile", "release", 3 * S)
    assert joy(m, 4 * S) == 0.0


def test_triggers_add_to_the_targets_and_the_neutral_key_lets_go():
    m = compile_mapping(doc(jaw={"source": "keys.1", "mode": "hold", "faps": {"open_jaw": 100}, "attack": 0},
                            tense={"source": "keys.2", "mode": "hold", "muscles": {"risorius_l": 0.5}, "attack": 0}))
    assert "risorius_l" in m.muscle_names
    key(m, "9", True, S)
    key(m, "1", True, S)
    key(m, "2", True, S)
    pose = m.pose(2 * S)
    assert pose.fap[2] == 400 and pose.muscles["risorius_l"] == 0.5
    assert m.channels()[0].targets == ("trigger jaw",)
    m.reset()
    assert not m.pose(3 * S).fap.any() and not m.trigger_states(3 * S)[0].active


def test_an_unknown_trigger_or_action_names_what_exists():
    m = compile_mapping(doc(smile={"mode": "hold", "expression": "joy"}, wow={"mode": "oneshot", "viseme": 3}),
                        "rig.yaml")
    assert m.trigger_names == ("smile", "wow")
    with pytest.raises(ValueError, match=r"^rig.yaml: no trigger 'smiel': expected one of smile, wow; "
                                         r"did you mean 'smile'\?$"):
        m.trigger("smiel", "press", S)
    with pytest.raises(ValueError, match="expected one of press, release, fire"):
        m.trigger("smile", "push", S)


# -- a clip of a take --------------------------------------------------------------------------

def _source_take(path: Path, fps: int = 30, frames: int = 75) -> np.ndarray:
    """A .fap whose jaw and brows move every frame; its values (frames x 68)."""
    rng = np.random.default_rng(3)
    values = np.zeros((frames, 68))
    values[:, 2] = np.round(300 + 250 * np.sin(np.arange(frames) / 5))
    values[:, 30:36] = rng.integers(-200, 200, (frames, 6))
    with FapWriter(path, fps, "nod") as writer:
        for row in values:
            write_pose(writer, row)
    return values


def test_a_clip_oneshot_writes_the_take_span_s_faps_into_a_take(tmp_path):
    source = _source_take(tmp_path / "nod.fap")
    m = compile_mapping(doc(nod={"source": "keys.1", "mode": "oneshot",
                                 "clip": {"take": "nod.fap", "from": 0.5, "to": 2.0}}), str(tmp_path / "m.yaml"))
    out = tmp_path / "out.fap"
    t0 = 7 * S
    with FapWriter(out, 30, "out") as writer:
        clock = TakeClock(m, lambda *frame: write_pose(writer, *frame), t0, 30)
        clock.apply(Sample(t0, "keys", {"1": 1.0}))
        clock.apply(Sample(t0 + S // 10, "keys", {"1": 0.0}))
        clock.apply(LogEvent(t0 + 2 * S, "frame"))
    written = read_fap(out).values
    np.testing.assert_array_equal(written[:45, 2:], source[15:60, 2:])   # 0.5 s .. 2.0 s at 30 fps
    assert not written[45:, 2:].any()                                   # then at rest


def test_a_clip_from_a_take_folder_fades_in_and_out_within_its_span(tmp_path, shared_runtime):
    folder = _record(shared_runtime, tmp_path, keys_mapping(tmp_path), lambda session: _performance(session, 0.0))
    m = compile_mapping(doc(nod={"mode": "oneshot", "clip": {"take": folder.name, "from": 0.1},
                                 "attack": 0.1, "release": 0.1, "ease": "linear"}), str(tmp_path / "m.yaml"))
    clip = m.triggers.all["nod"].spec.clip
    assert clip.frames.shape[1] == 68 and clip.seconds == pytest.approx((len(clip.frames) - 1) / 30, abs=0.02)
    assert m.triggers.all["nod"].spec.hold == pytest.approx(clip.seconds - 0.2)


# -- the checks ---------------------------------------------------------------------------------

def test_schema_and_checker_know_the_same_trigger_keys():
    defs = SCHEMA["$defs"]
    assert set(defs["trigger"]["properties"]) == set(TRIGGER_KEYS)
    assert set(defs["clip"]["properties"]) == set(CLIP_KEYS)
    assert defs["trigger"]["properties"]["mode"]["enum"] == list(MODES)
    assert defs["trigger"]["properties"]["ease"]["enum"] == list(EASES)


GOOD = {
    "a list with names": {**doc(), "triggers": [{"name": "smile", "source": "keys.1", "mode": "hold",
                                                 "expression": "joy"}]},
    "everything": doc(a={"source": "keys.1", "mode": "hold", "threshold": 0.3, "expression": 2, "viseme": 4,
                         "faps": {"open_jaw": 10, 5: -20}, "muscles": {"risorius_l": 1}, "strength": 0.5,
                         "attack": 0, "release": 1.5, "ease": "linear", "description": "all"},
                      b={"mode": "oneshot", "viseme": 14, "hold": 0}),
}

BAD = {
    "no mode": doc(smile={"expression": "joy"}),
    "bad mode": doc(smile={"mode": "latch", "expression": "joy"}),
    "no pose": doc(smile={"mode": "hold"}),
    "strength of 2": doc(smile={"mode": "hold", "expression": "joy", "strength": 2}),
    "negative attack": doc(smile={"mode": "hold", "expression": "joy", "attack": -1}),
    "hold on a toggle": doc(smile={"mode": "toggle", "expression": "joy", "hold": 1}),
    "clip on a hold": doc(smile={"mode": "hold", "clip": {"take": "x.fap"}}),
    "clip with an expression": doc(smile={"mode": "oneshot", "expression": "joy", "clip": {"take": "x.fap"}}),
    "clip without take": doc(smile={"mode": "oneshot", "clip": {"from": 1}}),
    "unknown key": doc(smile={"mode": "hold", "expression": "joy", "atack": 1}),
    "threshold without source": doc(smile={"mode": "hold", "expression": "joy", "threshold": 0.2}),
    "name inside a named trigger": doc(smile={"name": "smile", "mode": "hold", "expression": "joy"}),
    "a list item without a name": {**doc(), "triggers": [{"mode": "hold", "expression": "joy"}]},
    "faps is a list": doc(smile={"mode": "hold", "faps": [3]}),
    "triggers is a number": {**doc(), "triggers": 5},
}


@pytest.mark.parametrize("name", sorted(GOOD))
def test_good_trigger_documents_pass_both(name):
    assert list(VALIDATOR.iter_errors(GOOD[name])) == []
    compile_mapping(GOOD[name], "good.yaml")


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_trigger_documents_fail_both(name):
    assert list(VALIDATOR.iter_errors(BAD[name])), f"the schema accepts {name!r}"
    with pytest.raises(MappingError, match="^bad.yaml"):
        compile_mapping(BAD[name], "bad.yaml")


TEXT = """devices:
  keys: {url: "keys://"}
channels:
  keys.1:
  keys.2:
targets:
  - {fap: open_jaw, source: keys.2, range: [0, 300]}
triggers:
  smile: {source: keys.1, mode: hold, expression: joy}
"""


@pytest.mark.parametrize("line, message", [
    ("  smile: {source: keys.1, mode: hodl, expression: joy}",
     ("rig.yaml:9: triggers.smile.mode: expected a trigger mode: one of hold, toggle, oneshot, got 'hodl'; "
      "did you mean 'hold'?")),
    ("  smile: {source: keys.1, mode: hold, expression: jyo}",
     ("rig.yaml:9: triggers.smile.expression: expected an expression number 1-6 or name (joy, sadness, anger, fear, "
      "disgust, surprise), got 'jyo'; did you mean 'joy'?")),
    ("  smile: {source: keys.3, mode: hold, expression: joy}",
     ("rig.yaml:9: triggers.smile.source: source 'keys.3' is not a channel of the mapping: expected one of the "
      "channels; did you mean 'keys.2'? (add it under channels)")),
    ("  smile: {source: keys.1, mode: hold, expression: joy, relase: 0.3}",
     ("rig.yaml:9: triggers.smile.relase: unknown key 'relase' in trigger 'smile': expected one of "
      + ", ".join(TRIGGER_KEYS) + "; did you mean 'release'?")),
    ("  smile: {source: keys.1, mode: hold, faps: {opn_jaw: 300}}",
     ("rig.yaml:9: triggers.smile.faps.opn_jaw: expected a FAP name or number 3-68, got 'opn_jaw'; "
      "did you mean 'open_jaw'?")),
    ("  smile: {source: keys.1, mode: oneshot, clip: {take: takes/nod_009}}",
     ("rig.yaml:9: triggers.smile.clip.take: takes/nod_009: no such take (expected a take folder or a .fap file) "
      "(a clip's take is found relative to the mapping file)")),
])
def test_a_bad_trigger_is_one_line_naming_the_file_line_and_key(line, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(MappingError) as caught:
        parse_mapping(TEXT.replace(TEXT.splitlines()[-1], line), "rig.yaml")
    assert str(caught.value) == message


def test_a_clip_s_span_must_fit_its_take_and_its_blends(tmp_path):
    _source_take(tmp_path / "nod.fap", frames=31)  # 1 s at 30 fps
    past = doc(nod={"mode": "oneshot", "clip": {"take": "nod.fap", "from": 0.5, "to": 3}})
    assert "expected a span inside the take (31 frames at 30 fps: 0 to 1 s), got 0.5 to 3 s" in \
        str(pytest.raises(MappingError, compile_mapping, past, str(tmp_path / "m.yaml")).value)
    tight = doc(nod={"mode": "oneshot", "clip": {"take": "nod.fap", "to": 0.2}, "attack": 0.1, "release": 0.2})
    assert "attack + release (0.3 s) is longer than the clip (0.2 s)" in \
        str(pytest.raises(MappingError, compile_mapping, tight, str(tmp_path / "m.yaml")).value)


def test_a_keys_device_has_the_keys_the_window_does_not_keep():
    assert {"1", "9", "0", "a", "z", "f1", "f12"} <= set(KEY_NAMES)
    assert not WINDOW_KEYS & set(KEY_NAMES) and "f11" not in KEY_NAMES
    shown = {k.lower() for keys, _ in KEYS for k in keys.split() if len(k) == 1}
    assert shown == set(WINDOW_KEYS), "the cockpit's keys and the ones keys:// leaves to the window differ"
    bad = doc()
    bad["channels"]["keys.r"] = None
    assert "channels[\"keys.r\"]: key 'r' is the live window's own" in str(pytest.raises(
        MappingError, compile_mapping, bad).value)
    device = open_device("keys://", "keys")
    with pytest.raises(ValueError, match="keys: expected a key: .* got 'F13'"):
        device.push({"F13": 1.0})
    device.push({"f1": 1.0})
    assert device.backlog == 0 and len(device._read()) == 1


def test_the_guide_s_trigger_example_loads(tmp_path, shared_runtime):
    text = (ROOT / "docs" / "guide" / "mappings.md").read_text("utf-8")
    example = re.search(r"## Triggers.*?```yaml\n(.*?)```", text, re.DOTALL).group(1)
    (tmp_path / "takes").mkdir()
    folder = _record(shared_runtime, tmp_path / "takes", keys_mapping(tmp_path), lambda s: _performance(s, 0.0))
    folder.rename(tmp_path / "takes" / "nod_001")
    (tmp_path / "guide.yaml").write_text(example.replace("from: 0.5, to: 2.0", "from: 0.1, to: 0.4"))
    assert parse_mapping((tmp_path / "guide.yaml").read_text(), str(tmp_path / "guide.yaml")).trigger_names == (
        "smile", "wow", "angry", "nod")
    assert list(VALIDATOR.iter_errors(yaml.safe_load(example))) == []


# -- random presses ------------------------------------------------------------------------------

@settings(max_examples=200, deadline=None)
@given(mode=st.sampled_from(MODES), ease=st.sampled_from(EASES), attack=st.floats(0.01, 2.0),
       release=st.floats(0.01, 2.0), hold=st.floats(0.0, 1.0), strength=st.floats(0.05, 1.0),
       events=st.lists(st.tuples(st.integers(0, 3 * S), st.sampled_from(["press", "release", "fire", "key down",
                                                                          "key up"])), max_size=12))
def test_random_presses_keep_the_level_in_range_and_continuous(mode, ease, attack, release, hold, strength, events):
    spec = TriggerSpec("t", mode, "keys.1", 0.5, attack, release, hold if mode == "oneshot" else 0.0, ease,
                       strength, expression=1)
    trigger = Trigger(spec)
    slope = strength * (1.5 if ease == "smooth" else 1.0) / min(attack, release)  # per second, at most
    pending = sorted(events)
    last_t, last = 0, 0.0
    for t in range(0, 4 * S, S // 50):
        while pending and pending[0][0] <= t:
            at, action = pending.pop(0)
            before = trigger.level(at)
            if action.startswith("key"):
                trigger.input(1.0 if action == "key down" else 0.0, at)
            else:
                trigger.act(action, at)
            assert trigger.level(at) == pytest.approx(before, abs=1e-9)   # a press never jumps
        level = trigger.level(t)
        assert 0.0 <= level <= strength + 1e-12
        assert abs(level - last) <= slope * (t - last_t) / S + 1e-9
        last_t, last = t, level


# -- live: the window's keys and a take rebuilt ---------------------------------------------------

@pytest.fixture(scope="module")
def shared_runtime(face):
    return Runtime(face)


def keys_mapping(folder: Path) -> Path:
    path = folder / "keys.yaml"
    path.write_text("""devices:
  keys: {url: "keys://"}
channels:
  keys.1:
  keys.2:
targets:
  - {fap: open_jaw, source: keys.2, range: [0, 500]}
triggers:
  smile: {source: keys.1, mode: hold, expression: joy, attack: 0.15, release: 0.3}
  wow: {mode: oneshot, expression: surprise, attack: 0.05, hold: 0.1, release: 0.1}
""")
    return path


def _frames(session, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        session.frame()
        time.sleep(0.01)


def _performance(session, pause: float) -> None:
    keys = session.devices["keys"]
    keys.push({"1": 1.0})
    _frames(session, 0.25 + pause)
    session.trigger("wow", "fire")
    keys.push({"2": 1.0})
    _frames(session, 0.15)
    keys.push({"1": 0.0, "2": 0.0})
    _frames(session, 0.4)


def _record(runtime, root: Path, mapping: Path, perform) -> Path:
    with LiveSession(mapping, face=runtime, record_root=root, take_name="keys", fps=30) as session:
        assert isinstance(session.devices["keys"], KeysDevice)
        session.frame()
        session.start_recording()
        perform(session)
        return session.stop_recording()


def test_a_take_with_keys_and_triggers_by_name_is_rebuilt_exactly(shared_runtime, tmp_path):
    folder = _record(shared_runtime, tmp_path, keys_mapping(tmp_path), lambda session: _performance(session, 0.1))
    take = open_take(folder)
    events = [e for e in take.entries() if isinstance(e, LogEvent) and e.kind == "trigger"]
    assert [(e.data["name"], e.data["action"]) for e in events] == [("wow", "fire")]
    fap = read_fap(take.fap_path)
    selects, intensities = fap.expression[:, 0], fap.expression[:, 1]
    assert intensities[selects == 1].max() == 63      # the smile held full
    assert ((fap.expression[:, 2] == 6) & (fap.expression[:, 3] > 0)).any()  # surprise fired over it
    moved = np.ones(68, bool)
    moved[:2] = moved[[n - 1 for fapset in PART_FAPS.values() for n in fapset]] = False  # idle life goes on
    assert intensities[-1] == 0 and not fap.values[-1, moved].any()  # and all let go
    assert retake(take, tmp_path / "again.fap").identical
    assert retake(take, tmp_path / "wire.fap", through_devices=True).identical


def test_a_trigger_by_an_unknown_name_is_refused_at_once(shared_runtime, tmp_path):
    with LiveSession(keys_mapping(tmp_path), face=shared_runtime, record_root=tmp_path) as session:
        with pytest.raises(ValueError, match="no trigger 'wov': expected one of smile, wow; did you mean 'wow'"):
            session.trigger("wov", "fire")
        with pytest.raises(ValueError, match="trigger action 'tap'"):
            session.trigger("wow", "tap")


def _pixels(window, size) -> np.ndarray:
    return np.frombuffer(window.fbo.read(components=3), dtype=np.uint8).reshape(size[1], size[0], 3)[::-1].astype(int)


def test_key_1_in_the_live_window_holds_an_expression_and_the_cockpit_shows_it(tmp_path, headless_window):
    size = (320, 240)
    window = headless_window(size)
    session = open_session(keys_mapping(tmp_path), record_root=tmp_path)
    session.mapping.idle = None   # pixels back to rest exactly: no blinks (tests/test_idlelife.py)
    live = LiveView(session, window)
    assert trigger_keys(session) == "1 smile"

    def steps(seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            live.step()
            time.sleep(0.01)

    try:
        live._on_key(_Keys.H, _Keys.ACTION_PRESS, None)   # the cockpit hidden: the face alone
        steps(0.1)
        rest = _pixels(window, size)
        live._on_key(_Keys.NUMBER_1, _Keys.ACTION_PRESS, None)
        steps(0.4)
        held = _pixels(window, size)
        mouth = (slice(size[1] // 2, size[1] * 7 // 8), slice(size[0] // 3, size[0] * 2 // 3))
        assert np.abs(held[mouth] - rest[mouth]).mean() > 2
        assert (np.abs(held[mouth] - rest[mouth]).sum(axis=2) > 30).sum() > 150  # pixels that clearly moved
        live._on_key(_Keys.H, _Keys.ACTION_PRESS, None)   # the cockpit: the trigger's bar, lit
        steps(0.05)
        shown = _pixels(window, size)
        corner = (slice(size[1] - 40, size[1] - 8), slice(8, 200))
        assert np.abs(shown[corner] - held[corner]).mean() > 10
        live._on_key(_Keys.H, _Keys.ACTION_PRESS, None)
        live._on_key(_Keys.NUMBER_1, _Keys.ACTION_RELEASE, None)
        steps(0.5)                                         # the release (0.3 s) and more
        np.testing.assert_array_equal(_pixels(window, size), rest)
        live._on_key(_Keys.R, _Keys.ACTION_PRESS, None)    # the window's own keys keep their meaning
        assert session.recording
        live._on_key(_Keys.R, _Keys.ACTION_PRESS, None)
        assert not session.recording
    finally:
        live.close()
        session.close()


# -- the shipped mappings' triggers -----------------------------------------------------------------

def test_a_pad_of_the_midi_pad_mapping_plays_its_expression_once_through_the_midi_adapter():
    import mido

    from devices.midi_device import MessagePort, MidiDevice
    from puppet.io.shipped import shipped_mapping
    from puppet.live.mappingfile import load_mapping

    m = load_mapping(shipped_mapping("midi_pads"))
    port = MessagePort()
    with MidiDevice("pads", "LPD8", open_input=lambda name: port) as device:
        port.send(mido.Message("note_on", note=36, velocity=90))
        port.send(mido.Message("note_off", note=36))
        for sample in itertools.islice(device.samples(timeout=2.0), 2):
            m.feed(sample)
    t = sample.t_ns
    assert m.pose(t + S // 2).expression == (1, 63.0, 0, 0.0)     # joy: 0.1 s up, 0.8 s held
    assert m.pose(t + 2 * S).expression == (0, 0.0, 0, 0.0)       # and gone after its release


def test_what_a_key_drives_includes_its_triggers_for_a_layered_pass():
    from puppet.io.shipped import shipped_mapping
    from puppet.live.mappingfile import load_mapping

    m = load_mapping(shipped_mapping("arduino_sliders_keys"))
    assert m.drives("keys.1") == (set(), {"expression"})
    slots, kinds = m.drives("keys.7")
    assert slots == {16, 15, 5, 6} and kinds == set()   # the pout: push_t_lip, push_b_lip, stretch_l/r_cornerlip


def test_a_take_re_mapped_without_the_triggers_lets_their_presses_pass(shared_runtime, tmp_path):
    folder = _record(shared_runtime, tmp_path, keys_mapping(tmp_path), lambda session: _performance(session, 0.0))
    plain = tmp_path / "plain.yaml"
    plain.write_text(keys_mapping(tmp_path).read_text().split("triggers:")[0])
    result = retake(folder, tmp_path / "plain.fap", mapping=plain)
    values = read_fap(result.path)
    assert result.frames > 10 and values.values[:, 2].max() == 500 and not values.expression[:, 1].any()


def test_a_key_plays_its_trigger_while_another_device_is_away_and_the_take_agrees(shared_runtime, tmp_path):
    from devices import State
    from devices.pushed_device import PushedDevice

    class Box(PushedDevice):
        """A box that can be pulled out: its reads and reopens fail while ``away``."""

        away = False

        def _open(self) -> None:
            if self.away:
                raise OSError("unplugged")

        def _read(self):
            if self.away:
                raise OSError("unplugged")
            return super()._read()

    mapping = tmp_path / "box.yaml"
    mapping.write_text(keys_mapping(tmp_path).read_text().replace(
        'devices:\n', 'devices:\n  box: {url: "api://"}\n').replace(
        'channels:\n', 'channels:\n  box.jaw:\n').replace(
        'targets:\n', 'targets:\n  - {fap: open_jaw, source: box.jaw, range: [0, 200]}\n'))
    box = Box("box")
    box.BACKOFF = (0.01, 0.05)
    with LiveSession(mapping, face=shared_runtime, devices={"box": box}, record_root=tmp_path, fps=30) as session:
        _frames(session, 0.1)
        session.start_recording()
        box.push({"jaw": 0.5})
        _frames(session, 0.1)
        box.away = True
        assert box.wait_state(State.LOST, 2.0)
        _frames(session, 0.05)
        session.devices["keys"].push({"1": 1.0})
        _frames(session, 0.3)
        frame = session.frame()
        assert frame.states["box"] is not State.OPEN and frame.pose.expression[:2] == (1, 63.0)
        assert frame.pose.fap[2] == 100    # the box's jaw held where it was
        box.away = False
        assert box.wait_state(State.OPEN, 2.0)
        _frames(session, 0.1)
        folder = session.stop_recording()
    take = open_take(folder)
    assert {e.kind for e in take.entries() if isinstance(e, LogEvent)} >= {"hold", "resume"}
    assert (read_fap(take.fap_path).expression[:, 1] == 63).any()
    assert retake(take, tmp_path / "again.fap").identical
