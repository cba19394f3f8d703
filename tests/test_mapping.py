"""Mappings: the shipped files, the schema and the Python checker kept in step, every error path
with its message, the shaping maths, and samples -> Pose end to end."""

import copy
import itertools
import json
import math
import time
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from devices.base import Sample
from puppet import MappingError, load_mapping
from puppet.face.muscles import MUSCLE_NAMES
from puppet.fap.highlevel import high_level_faps
from puppet.fap.pose import Pose
from puppet.fap.table import faps
from puppet.fap.units import AU
from puppet.live.channels import COMBINE_MODES, EXPRESSIONS
from puppet.live.mappingfile import (
    BUTTON_KEYS,
    BUTTON_MODES,
    CHANNEL_KEYS,
    CURVE_KEYS,
    DEVICE_KEYS,
    RANGES,
    ROOT_KEYS,
    SMOOTHING_KEYS,
    TARGET_KEYS,
    compile_mapping,
    fap_names,
    parse_mapping,
)

MAPPINGS = Path(__file__).resolve().parents[1] / "mappings"
SCHEMA = json.loads((MAPPINGS / "schema.json").read_text())
VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)
MS = 1_000_000


def base(**channel):
    """A one-device, one-channel, one-target document to vary."""
    return {
        "devices": {"box": {"url": "serial:///dev/ttyACM0"}},
        "channels": {"box.ch0": dict(channel)},
        "targets": [{"fap": "open_jaw", "source": "box.ch0", "range": [0, 600]}],
    }


def with_(doc, path, value):
    """A deep copy of doc with doc[path...] = value."""
    doc = copy.deepcopy(doc)
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return doc


def without(doc, path):
    doc = copy.deepcopy(doc)
    node = doc
    for key in path[:-1]:
        node = node[key]
    del node[path[-1]]
    return doc


def error_of(doc, file="m.yaml") -> MappingError:
    with pytest.raises(MappingError) as info:
        compile_mapping(doc, file)
    return info.value


def yaml_error(text, file="m.yaml") -> MappingError:
    with pytest.raises(MappingError) as info:
        parse_mapping(text, file)
    return info.value


def shaped(channel: dict, raws, step_ms=10) -> list[float]:
    """The shaped value of box.ch0 after each raw value (samples step_ms apart)."""
    m = compile_mapping(base(**channel))
    out = []
    for i, raw in enumerate(raws):
        m.feed(Sample(1_000 * MS + i * step_ms * MS, "box", {"ch0": raw}))
        out.append(m.channels()[0].value)
    return out


# -- the shipped mappings, the schema and the checker -----------------------------------------

SHIPPED = ["arduino_sliders.yaml", "gamepad_hid.yaml", "can_joystick.yaml", "midi_faders.yaml", "arkit_osc.yaml",
           "voice.yaml", "arduino_sliders_voice.yaml", "arduino_sliders_keys.yaml", "midi_pads.yaml",
           "arkit_csv.yaml"]


def test_schema_is_a_valid_2020_12_schema():
    assert SCHEMA["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    jsonschema.Draft202012Validator.check_schema(SCHEMA)


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_mapping_loads_and_follows_the_schema(name):
    path = MAPPINGS / name
    errors = [e.message for e in VALIDATOR.iter_errors(yaml.safe_load(path.read_text()))]
    assert errors == []
    m = load_mapping(path)
    assert m.devices and all("://" in url for url in m.devices.values())
    assert all(c.targets for c in m.channels()), "every channel of a shipped mapping drives something"
    pose = m.pose()
    assert pose.fap.shape == (68,) and not pose.fap.any()


def test_no_other_mapping_files_are_unchecked():
    assert sorted(p.name for p in MAPPINGS.glob("*.yaml")) == sorted(SHIPPED)


GOOD = {
    "minimal": base(),
    "null channel": with_(base(), ["channels", "box.ch0"], None),
    "everything": {
        "description": "all features",
        "devices": {"box": {"url": "serial:///dev/ttyACM0", "options": {"baudrate": 115200, "exclusive": True},
                            "description": "slider box"},
                    "pad-1": {"url": "hid://046d:c21d"}},
        "channels": {
            "box.ch0": {"range": "bipolar", "min": 0, "centre": 500, "max": 1023, "invert": True,
                        "dead_zone": 0.1, "curve": {"type": "points", "points": [[0, 0], [0.5, 0.2], [1, 1]]},
                        "smoothing": {"type": "one_euro", "min_cutoff": 1.0, "beta": 0.1, "d_cutoff": 1.0},
                        "rate_limit": 5, "description": "brow"},
            "box.ch1": {"curve": {"type": "expo", "factor": 0.5}, "smoothing": {"type": "exponential", "tau": 0.05}},
            "box.ch2": {"curve": {"type": "gamma", "gamma": 2.2}, "smoothing": {"type": "one_euro"}},
            "box.ch3": {"curve": {"type": "linear"}},
            "pad-1.A": {"button": {"mode": "toggle", "threshold": 0.6, "release": 0.4}},
            "pad-1.fader/1": {"button": {"mode": "momentary"}},
        },
        "targets": [
            {"fap": "raise_l_i_eyebrow", "source": "box.ch0", "range": [-200, 200], "gain": 0.5},
            {"fap": 3, "source": ["box.ch1", "box.ch2", "pad-1.A"], "combine": "max", "range": [0, 600]},
            {"muscle": "zygomatic_major_l", "source": "box.ch3"},
            {"viseme": 10, "source": "box.ch1", "range": [0, 63]},
            {"expression": "joy", "source": "pad-1.A"},
            {"expression": 6, "source": "pad-1.fader/1", "combine": "last"},
            {"head": "roll", "source": "box.ch0", "range": [-10, 10]},
            {"eyes": "pitch", "source": "box.ch0", "range": [-20, 20]},
            {"eye_l": "yaw", "source": "box.ch0", "range": [-20, 20]},
            {"eye_r": "yaw", "source": "box.ch0", "range": [-20, 20], "description": "r"},
        ],
    },
}

# Documents that break the format itself: both the schema and the checker refuse them.
BAD = {
    "root is a list": [1, 2],
    "root is a string": "devices",
    "unknown top-level key": with_(base(), ["target"], []),
    "missing targets": without(base(), ["targets"]),
    "no devices": with_(base(), ["devices"], {}),
    "device name with a dot": with_(base(), ["devices"], {"b.x": {"url": "serial:///dev/x"}}),
    "device without url": with_(base(), ["devices", "box"], {"options": {}}),
    "url without scheme": with_(base(), ["devices", "box", "url"], "/dev/ttyACM0"),
    "unknown device key": with_(base(), ["devices", "box", "baud"], 9600),
    "option is a list": with_(base(), ["devices", "box", "options"], {"baudrate": [1]}),
    "channel key without device": with_(base(), ["channels"], {"ch0": {}}),
    "unknown channel option": base(deadzone=0.1),
    "bad range word": base(range="bipolarr"),
    "min is text": base(min="zero"),
    "invert is a number": base(invert=1),
    "dead zone of 1": base(dead_zone=1.0),
    "negative dead zone": base(dead_zone=-0.1),
    "centre on a unipolar channel": base(centre=0.5),
    "centre with range unipolar": base(range="unipolar", centre=0.5),
    "curve is a word": base(curve="expo"),
    "curve without type": base(curve={"factor": 0.3}),
    "unknown curve type": base(curve={"type": "expp", "factor": 0.3}),
    "expo without factor": base(curve={"type": "expo"}),
    "expo factor above 1": base(curve={"type": "expo", "factor": 1.5}),
    "gamma of 0": base(curve={"type": "gamma", "gamma": 0}),
    "key of another curve type": base(curve={"type": "expo", "factor": 0.3, "gamma": 2}),
    "one point": base(curve={"type": "points", "points": [[0, 0]]}),
    "point of three numbers": base(curve={"type": "points", "points": [[0, 0, 0], [1, 1]]}),
    "point above 1": base(curve={"type": "points", "points": [[0, 0], [1, 2]]}),
    "unknown smoothing type": base(smoothing={"type": "kalman"}),
    "exponential without tau": base(smoothing={"type": "exponential"}),
    "zero min_cutoff": base(smoothing={"type": "one_euro", "min_cutoff": 0}),
    "negative beta": base(smoothing={"type": "one_euro", "beta": -1}),
    "tau on one euro": base(smoothing={"type": "one_euro", "tau": 0.1}),
    "zero rate limit": base(rate_limit=0),
    "min_cutoff of 1e308": base(smoothing={"type": "one_euro", "min_cutoff": 1e308}),
    "beta of 1e308": base(smoothing={"type": "one_euro", "beta": 1e308}),
    "tau of a year": base(smoothing={"type": "exponential", "tau": 3.2e7}),
    "max of 1e13": base(max=1e13),
    "gamma of 1e308": base(curve={"type": "gamma", "gamma": 1e308}),
    "rate limit of 1e308": base(rate_limit=1e308),
    "threshold of 2": base(button={"mode": "toggle", "threshold": 2}),
    "target range of 1e308": with_(base(), ["targets", 0, "range"], [-1e308, 1e308]),
    "gain of 1e308": with_(base(), ["targets", 0, "gain"], 1e308),
    "button without mode": base(button={"threshold": 0.5}),
    "bad button mode": base(button={"mode": "latch"}),
    "button with dead zone": base(button={"mode": "toggle"}, dead_zone=0.1),
    "button with curve": base(button={"mode": "toggle"}, curve={"type": "linear"}),
    "no targets": with_(base(), ["targets"], []),
    "target is a string": with_(base(), ["targets", 0], "open_jaw"),
    "target without kind": with_(base(), ["targets", 0], {"source": "box.ch0", "range": [0, 1]}),
    "target with two kinds": with_(base(), ["targets", 0, "muscle"], "m"),
    "target without source": without(base(), ["targets", 0, "source"]),
    "unknown target key": with_(base(), ["targets", 0, "sauce"], "box.ch0"),
    "bad FAP name": with_(base(), ["targets", 0, "fap"], "opn_jaw"),
    "FAP number 69": with_(base(), ["targets", 0, "fap"], 69),
    "FAP 1 as a value": with_(base(), ["targets", 0, "fap"], 1),
    "FAP named viseme": with_(base(), ["targets", 0, "fap"], "viseme"),
    "fap without range": without(base(), ["targets", 0, "range"]),
    "range of one number": with_(base(), ["targets", 0, "range"], [0]),
    "range of three numbers": with_(base(), ["targets", 0, "range"], [0, 1, 2]),
    "range with text": with_(base(), ["targets", 0, "range"], [0, "max"]),
    "range is a number": with_(base(), ["targets", 0, "range"], 600),
    "bad combine mode": with_(base(), ["targets", 0, "combine"], "summ"),
    "gain is text": with_(base(), ["targets", 0, "gain"], "half"),
    "source without dot": with_(base(), ["targets", 0, "source"], "ch0"),
    "empty source list": with_(base(), ["targets", 0, "source"], []),
    "muscle with capitals": with_(base(), ["targets", 0], {"muscle": "Zygomatic", "source": "box.ch0"}),
    "viseme 15": with_(base(), ["targets", 0], {"viseme": 15, "source": "box.ch0"}),
    "viseme 0": with_(base(), ["targets", 0], {"viseme": 0, "source": "box.ch0"}),
    "unknown expression": with_(base(), ["targets", 0], {"expression": "jy", "source": "box.ch0"}),
    "expression 7": with_(base(), ["targets", 0], {"expression": 7, "source": "box.ch0"}),
    "head axis": with_(base(), ["targets", 0], {"head": "yawn", "source": "box.ch0", "range": [0, 1]}),
    "eyes roll": with_(base(), ["targets", 0], {"eyes": "roll", "source": "box.ch0", "range": [0, 1]}),
    "head without range": with_(base(), ["targets", 0], {"head": "yaw", "source": "box.ch0"}),
    "description is a number": with_(base(), ["description"], 5),
}

# Documents whose every part has the right form, but that are still wrong in ways a JSON schema
# cannot say (relations between values, references between sections). The schema accepts them;
# the checker refuses them. A new check added to one side only shows up here.
BEYOND_THE_SCHEMA = {
    "max not above min": base(min=10, max=5),
    "centre outside min..max": base(range="bipolar", min=0, centre=2000, max=1023),
    "points with x falling": base(curve={"type": "points", "points": [[0, 0], [0.6, 0.5], [0.4, 0.6], [1, 1]]}),
    "points with y falling": base(curve={"type": "points", "points": [[0, 0], [0.5, 0.8], [1, 0.6]]}),
    "points not from 0 to 1": base(curve={"type": "points", "points": [[0.1, 0], [1, 1]]}),
    "bipolar curve not through 0": base(range="bipolar", curve={"type": "points", "points": [[0, 0.2], [1, 1]]}),
    "release above threshold": base(button={"mode": "toggle", "threshold": 0.5, "release": 0.7}),
    "channel of an undefined device": with_(base(), ["channels", "pad.X"], {}),
    "source of an undefined device": with_(base(), ["targets", 0, "source"], "pad.X"),
    "source of an undefined channel": with_(base(), ["targets", 0, "source"], "box.ch9"),
    "sources of mixed polarity": with_(with_(base(), ["channels", "box.ch1"], {"range": "bipolar"}),
                                       ["targets", 0, "source"], ["box.ch0", "box.ch1"]),
    "option also in the url": with_(base(), ["devices", "box"], {"url": "serial:///dev/x?baudrate=9600",
                                                                  "options": {"baudrate": 115200}}),
}


@pytest.mark.parametrize("name", sorted(GOOD))
def test_good_documents_pass_both(name):
    assert list(VALIDATOR.iter_errors(GOOD[name])) == []
    compile_mapping(GOOD[name], "good.yaml")


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_documents_fail_both(name):
    assert list(VALIDATOR.iter_errors(BAD[name])), f"the schema accepts {name!r}"
    err = error_of(BAD[name], "bad.yaml")
    assert str(err).startswith("bad.yaml")


@pytest.mark.parametrize("name", sorted(BEYOND_THE_SCHEMA))
def test_relations_the_schema_cannot_express_are_checked_in_python(name):
    assert list(VALIDATOR.iter_errors(BEYOND_THE_SCHEMA[name])) == []
    error_of(BEYOND_THE_SCHEMA[name])


def test_schema_and_checker_know_the_same_keys_and_names():
    defs = SCHEMA["$defs"]
    assert set(SCHEMA["properties"]) == set(ROOT_KEYS)
    assert set(defs["device"]["properties"]) == set(DEVICE_KEYS)
    assert set(defs["channel"]["properties"]) == set(CHANNEL_KEYS)
    assert set(defs["channel"]["properties"]["range"]["enum"]) == set(RANGES)
    assert set(defs["button"]["properties"]) == set(BUTTON_KEYS)
    assert set(defs["button"]["properties"]["mode"]["enum"]) == set(BUTTON_MODES)
    assert set(defs["target"]["properties"]) == set(TARGET_KEYS)
    assert set(defs["target"]["properties"]["combine"]["enum"]) == set(COMBINE_MODES)
    fap_enum = defs["target"]["properties"]["fap"]["anyOf"][1]["enum"]
    assert fap_enum == fap_names() == [f.name for f in faps()][2:]
    assert defs["target"]["properties"]["expression"]["anyOf"][1]["enum"] == list(EXPRESSIONS)
    assert defs["target"]["properties"]["muscle"]["enum"] == list(MUSCLE_NAMES)
    for kind, section in (("curve", CURVE_KEYS), ("smoothing", SMOOTHING_KEYS)):
        assert set(defs[kind]["properties"]["type"]["enum"]) == set(section)
        for rule in defs[kind]["allOf"]:
            t = rule["if"]["properties"]["type"]["const"]
            assert set(rule["then"]["properties"]) == {"type", *section[t]}


# -- every error path, with its message --------------------------------------------------------

def test_unknown_top_level_key_names_file_path_expected_and_closest():
    text = ("devices:\n  box: {url: 'serial:///dev/x'}\nchannels:\n  box.ch0: {}\n"
            "targets:\n  - {fap: open_jaw, source: box.ch0, range: [0, 600]}\ntarget: []\n")
    msg = str(yaml_error(text, "rig.yaml"))
    assert msg.startswith("rig.yaml:7: target: unknown key 'target'")
    assert "expected one of devices, channels, targets, description" in msg
    assert "did you mean 'targets'?" in msg


def test_unknown_channel_option():
    msg = str(error_of(base(deadzone=0.1), "rig.yaml"))
    assert msg.startswith('rig.yaml: channels["box.ch0"].deadzone: unknown key \'deadzone\'')
    assert "expected one of range, min, centre, max" in msg and "did you mean 'dead_zone'?" in msg


def test_bad_fap_name_suggests_the_closest():
    msg = str(error_of(with_(base(), ["targets", 0, "fap"], "opn_jaw"), "rig.yaml"))
    assert msg == ("rig.yaml: targets[0].fap: expected a FAP name or number 3-68, got 'opn_jaw'; "
                   "did you mean 'open_jaw'?")
    msg = str(error_of(with_(base(), ["targets", 0, "fap"], "rasie_l_cornerlip")))
    assert "did you mean 'raise_l_cornerlip'?" in msg
    msg = str(error_of(with_(base(), ["targets", 0, "fap"], 1)))
    assert "targets[0].fap: FAP 1 is not a value" in msg and "viseme: target" in msg


@pytest.mark.parametrize("bad", [[0], [0, 1, 2], [0, "max"], 600, [0, float("nan")]])
def test_range_must_be_two_numbers(bad):
    msg = str(error_of(with_(base(), ["targets", 0, "range"], bad), "rig.yaml"))
    assert msg.startswith("rig.yaml: targets[0].range: expected two numbers [low, high] in FAPU units, each from "
                          "-1e+06 to 1e+06, got ")


def test_head_range_is_in_degrees_and_required():
    doc = with_(base(), ["targets", 0], {"head": "yaw", "source": "box.ch0"})
    assert "targets[0]: missing key 'range': expected range: [low, high] in degrees" in str(error_of(doc))


def test_source_naming_an_undefined_device_or_channel():
    msg = str(error_of(with_(base(), ["targets", 0, "source"], "bx.ch0"), "rig.yaml"))
    assert msg.startswith("rig.yaml: targets[0].source: source 'bx.ch0' names device 'bx', which is not defined")
    assert "expected one of the devices (box); did you mean 'box'?" in msg
    msg = str(error_of(with_(base(), ["targets", 0, "source"], ["box.ch0", "box.ch9"])))
    assert "targets[0].source[1]: source 'box.ch9' is not a channel of the mapping" in msg
    assert "did you mean 'box.ch0'?" in msg
    msg = str(error_of(with_(base(), ["channels", "pad.X"], {})))
    assert "channels[\"pad.X\"]: device 'pad' is not defined" in msg


def test_bad_combine_mode():
    msg = str(error_of(with_(base(), ["targets", 0, "combine"], "maximum"), "rig.yaml"))
    assert msg == ("rig.yaml: targets[0].combine: expected a combine mode: one of sum, max, last, "
                   "got 'maximum'; did you mean 'max'?")


def test_bad_curve_points_and_types():
    msg = str(error_of(base(curve={"type": "points", "points": [[0, 0], [0.6, 0.5], [0.4, 0.6], [1, 1]]})))
    assert 'channels["box.ch0"].curve.points[2]: expected x strictly rising (a monotonic curve), ' \
           'got x = 0.4 after x = 0.6' in msg
    msg = str(error_of(base(curve={"type": "points", "points": [[0, 0], [0.5, 0.8], [1, 0.6]]})))
    assert "curve.points[2]: expected y never falling (a monotonic curve), got y = 0.6 after y = 0.8" in msg
    msg = str(error_of(base(curve={"type": "exponential", "factor": 0.3})))
    assert "curve.type: expected a curve type: one of linear, expo, gamma, points, got 'exponential'; " \
           "did you mean" in msg
    msg = str(error_of(base(smoothing={"type": "one_eur"})))
    assert "smoothing.type: expected a smoothing type: one of one_euro, exponential, got 'one_eur'; " \
           "did you mean 'one_euro'?" in msg
    msg = str(error_of(base(smoothing={"type": "one_euro", "mincutoff": 1})))
    assert "smoothing.mincutoff: unknown key 'mincutoff'" in msg and "did you mean 'min_cutoff'?" in msg


def test_yaml_syntax_error_gives_the_line():
    text = "devices:\n  box: {url: 'serial:///dev/x'}\nchannels:\n  box.ch0: {min: [0, 1}\n"
    err = yaml_error(text, "rig.yaml")
    assert str(err).startswith("rig.yaml:4: YAML syntax error at line 4, column")
    err = yaml_error("devices:\n\tbox: 1\n", "tabs.yaml")
    assert str(err).startswith("tabs.yaml:2: YAML syntax error at line 2")


def test_a_line_indented_too_little_is_the_line_named_not_the_one_after_it():
    """PyYAML notices a key that lost its indentation only at the next, deeper line; the error
    names the line that went wrong."""
    text = ("devices:\n  box: {url: 'serial:///dev/x'}\nchannels:\n  box.ch0:\n    min: 0\n"
            "  smoothing: {type: exponential, tau: 0.1}\n    dead_zone: 0.1\n")
    err = str(yaml_error(text, "indent.yaml"))
    assert err.startswith("indent.yaml:6: YAML indentation: line 6 is indented 2 spaces") and "line 7" in err
    deeper = "devices:\n  box: {url: 'serial:///dev/x'}\nchannels:\n  box.ch0:\n    min: 0\n      max: 5\n"
    assert str(yaml_error(deeper, "deeper.yaml")).startswith("deeper.yaml:6: YAML syntax error at line 6")


def test_a_plain_value_that_lost_its_indentation_is_named_not_the_line_after_it():
    """After ``key: 0.1`` (a plain value, which YAML could carry on to the next line) PyYAML says
    "mapping values are not allowed" at the next, deeper line; the line that went wrong is named."""
    text = ("devices:\n  box: {url: 'serial:///dev/x'}\nchannels:\n  box.ch0:\n    min: 0\n"
            "  dead_zone: 0.1\n    max: 1023\n")
    err = str(yaml_error(text, "plain.yaml"))
    assert err.startswith("plain.yaml:6: YAML indentation: line 6 is indented 2 spaces") and "line 7" in err


def test_a_line_between_two_indentations_says_which_two():
    text = "devices:\n  box: {url: 'serial:///dev/x'}\nchannels:\n  box.ch0:\n    min: 0\n   max: 1023\n"
    err = str(yaml_error(text, "between.yaml"))
    assert err == ("between.yaml:6: YAML indentation: line 6 is indented 3 spaces, less than line 5 (4) and more "
                   "than the keys from line 4 (2), so it fits in neither; give it the indentation of the keys it "
                   "belongs with")


@pytest.mark.parametrize("text, got", [("- 1\n- 2\n", "[1, 2]"), ("hello\n", "'hello'"), ("", "nothing"),
                                       ("# only a comment\n", "nothing")])
def test_non_mapping_root(text, got):
    msg = str(yaml_error(text, "rig.yaml"))
    assert "expected a mapping with the keys devices, channels and targets at the top of the file" in msg
    assert msg.startswith("rig.yaml") and msg.endswith(f"got {got}")


def test_duplicate_keys_are_errors_not_silently_dropped():
    text = ("devices:\n  box: {url: 'serial:///dev/x'}\nchannels:\n  box.ch0: {min: 0, min: 5}\n"
            "targets:\n  - {fap: open_jaw, source: box.ch0, range: [0, 600]}\n")
    msg = str(yaml_error(text, "rig.yaml"))
    assert msg.startswith('rig.yaml:4: channels["box.ch0"].min: duplicate key \'min\' (first on line 4)')


def test_the_whole_file_is_checked_and_lines_are_right():
    text = ("devices:\n"                                              # 1
            "  box: {url: 'serial:///dev/x'}\n"                       # 2
            "channels:\n"                                             # 3
            "  box.ch0:\n"                                            # 4
            "    dead_zone: 2\n"                                      # 5
            "  box.ch1: {curve: {type: gama, gamma: 2}}\n"            # 6
            "targets:\n"                                              # 7
            "  - {fap: open_jaw, source: box.ch0, range: [0, 600]}\n"  # 8
            "  - fap: opn_jaw\n"                                      # 9
            "    source: box.ch1\n"                                   # 10
            "    range: [0, 1]\n"                                     # 11
            "  - {muscle: risorius_l, source: box.ch0, combine: sun}\n")  # 12
    err = yaml_error(text, "rig.yaml")
    assert [(p.line, p.path) for p in err.problems] == [
        (5, 'channels["box.ch0"].dead_zone'), (6, 'channels["box.ch1"].curve.type'),
        (9, "targets[1].fap"), (12, "targets[2].combine")]
    assert len(str(err).splitlines()) == 4


def test_a_missing_file_is_a_mapping_error(tmp_path):
    with pytest.raises(MappingError, match="nothere.yaml: cannot read the mapping"):
        load_mapping(tmp_path / "nothere.yaml")


def test_nothing_in_a_mapping_is_executed():
    text = "!!python/object/apply:os.system ['echo pwned']\n"
    assert str(yaml_error(text, "evil.yaml")).startswith("evil.yaml:1: unsupported YAML at line 1")
    text = "devices: !!python/name:os.system\n"
    assert "expected plain data" in str(yaml_error(text))


def test_nested_aliases_do_not_blow_up():
    lol = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n" for p, c in zip("abcdefgh", "bcdefghi"))
    t0 = time.perf_counter()
    err = yaml_error(lol)
    assert time.perf_counter() - t0 < 5
    assert "expected YAML aliases to add at most 10,000 values when expanded" in str(err)


# -- the maths of a channel --------------------------------------------------------------------

def test_bipolar_calibration_maps_min_centre_max_and_clamps():
    ch = {"range": "bipolar", "min": 100, "centre": 400, "max": 900}
    assert shaped(ch, [100, 400, 900, 250, 650, -5000, 5000]) == [-1.0, 0.0, 1.0, -0.5, 0.5, -1.0, 1.0]
    # centre defaults to midway
    assert shaped({"range": "bipolar", "min": 0, "max": 1000}, [500, 0, 750]) == [0.0, -1.0, 0.5]


def test_unipolar_calibration_and_invert():
    assert shaped({"min": 10, "max": 20}, [10, 15, 20, 0, 99]) == [0.0, 0.5, 1.0, 0.0, 1.0]
    assert shaped({"min": 10, "max": 20, "invert": True}, [10, 15, 20, 0, 99]) == [1.0, 0.5, 0.0, 1.0, 0.0]
    assert shaped({"range": "bipolar", "invert": True}, [-1, 0, 0.5, 1]) == [1.0, -0.0, -0.5, -1.0]


@settings(max_examples=150, deadline=None)
@given(dead=st.floats(0.0, 0.9), bipolar=st.booleans(), eps=st.floats(1e-9, 1e-3))
def test_dead_zone_is_zero_inside_and_continuous_at_its_edge(dead, bipolar, eps):
    ch = {"range": "bipolar" if bipolar else "unipolar", "dead_zone": dead}
    inside = [dead * k / 4 for k in range(5)]
    values = shaped(ch, inside + [min(dead + eps, 1.0), 1.0])
    assert all(v == 0.0 for v in values[:5])
    just_out, full = values[5], values[6]
    assert 0.0 <= just_out <= eps / (1.0 - dead) + 1e-12        # 0 at the edge, slope 1 / (1 - dead)
    assert full == 1.0
    if bipolar:
        assert shaped(ch, [-(dead + eps)])[0] == pytest.approx(-just_out, abs=1e-15)


@settings(max_examples=150, deadline=None)
@given(curve=st.one_of(
    st.builds(lambda k: {"type": "expo", "factor": k}, st.floats(0.0, 1.0)),
    st.builds(lambda g: {"type": "gamma", "gamma": g}, st.floats(0.05, 8.0)),
    st.lists(st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)), min_size=0, max_size=6).map(
        lambda pts: {"type": "points", "points": [[0.0, 0.0]] + sorted(
            [[x, y] for x, y in zip(sorted({p[0] for p in pts if 0 < p[0] < 1}), sorted(p[1] for p in pts))])
            + [[1.0, 1.0]]})),
    dead=st.floats(0.0, 0.5), bipolar=st.booleans(),
    raws=st.lists(st.floats(-1.5, 1.5), min_size=2, max_size=30))
def test_the_whole_shaping_is_monotonic(curve, dead, bipolar, raws):
    """Calibration, dead zone and every curve type: a larger raw value never reads smaller."""
    ch = {"range": "bipolar" if bipolar else "unipolar", "dead_zone": dead, "curve": curve}
    raws = sorted(raws)
    values = shaped(ch, raws)
    assert all(b >= a for a, b in itertools.pairwise(values))
    ends = shaped(ch, [-1.0 if bipolar else 0.0, 1.0])
    assert ends == [-1.0 if bipolar else 0.0, 1.0]


def test_curve_values():
    assert shaped({"curve": {"type": "expo", "factor": 0.5}}, [0.5]) == [0.5 * 0.5 + 0.5 * 0.125]
    assert shaped({"curve": {"type": "gamma", "gamma": 2}}, [0.5]) == [0.25]
    pts = {"type": "points", "points": [[0, 0], [0.5, 0.2], [1, 1]]}
    assert shaped({"curve": pts}, [0.25, 0.5, 0.75]) == pytest.approx([0.1, 0.2, 0.6])
    assert shaped({"range": "bipolar", "curve": pts}, [-0.25, 0.75]) == pytest.approx([-0.1, 0.6])


@settings(max_examples=40, deadline=None)
@given(rate=st.floats(0.5, 50.0), raws=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=40),
       step_ms=st.integers(1, 40))
def test_rate_limit_bounds_the_slope_of_a_channel(rate, raws, step_ms):
    values = shaped({"rate_limit": rate}, raws, step_ms)
    for a, b in itertools.pairwise(values):
        assert abs(b - a) <= rate * step_ms / 1000 + 1e-12


def test_exponential_smoothing_step_response_through_a_channel():
    tau = 0.05
    values = shaped({"smoothing": {"type": "exponential", "tau": tau}}, [0.0] + [1.0] * 20, step_ms=7)
    for k, v in enumerate(values):
        assert v == pytest.approx(1 - math.exp(-k * 0.007 / tau), abs=1e-12)


def test_order_is_calibrate_invert_deadzone_curve_then_filters():
    ch = {"min": 0, "max": 100, "invert": True, "dead_zone": 0.2, "curve": {"type": "gamma", "gamma": 2},
          "smoothing": {"type": "exponential", "tau": 0.01}}
    # raw 20 -> 0.2 -> inverted 0.8 -> dead zone (0.8 - 0.2) / 0.8 = 0.75 -> squared 0.5625
    assert shaped(ch, [20]) == [pytest.approx(0.5625, abs=1e-15)]
    # the filter acts on the shaped value: a step from 0.5625 to 0 decays exponentially
    values = shaped(ch, [20, 100], step_ms=10)
    assert values[1] == pytest.approx(0.5625 * math.exp(-1.0), abs=1e-12)


# -- samples to Pose ----------------------------------------------------------------------------

def two_devices(**target):
    return {
        "devices": {"box": {"url": "serial:///dev/ttyACM0"}, "pad": {"url": "hid://046d:c21d"}},
        "channels": {"box.ch0": {"min": 0, "max": 1000}, "box.ch1": {"min": 0, "max": 1000},
                     "pad.X": {"range": "bipolar", "min": -100, "centre": 0, "max": 100},
                     "pad.A": {"button": {"mode": "momentary"}},
                     "pad.B": {"button": {"mode": "toggle", "threshold": 0.6, "release": 0.3}}},
        "targets": [target] if target else [
            {"fap": "open_jaw", "source": "box.ch0", "range": [0, 600]},
            {"fap": 12, "source": "box.ch1", "range": [0, 200]},
            {"fap": "raise_r_cornerlip", "source": "box.ch1", "range": [0, 200], "gain": 0.5},
            {"head": "yaw", "source": "pad.X", "range": [-30, 30]},
            {"eyes": "pitch", "source": "pad.X", "range": [20, -20]},
            {"fap": "close_t_l_eyelid", "source": "pad.A", "range": [0, 900]},
            {"muscle": "zygomatic_major_l", "source": "box.ch1"},
            {"muscle": "zygomatic_major_l", "source": "box.ch1"},
        ],
    }


def fap_of(pose: Pose, name_or_number):
    number = name_or_number if isinstance(name_or_number, int) else fap_names().index(name_or_number) + 3
    return pose.fap[number - 1]


def test_samples_from_two_devices_give_the_expected_faps():
    m = compile_mapping(two_devices())
    m.feed(Sample(1 * MS, "box", {"ch0": 250, "ch1": 500, "ch7": 3}))
    m.feed(Sample(2 * MS, "pad", {"X": 50, "A": 1, "Y": 9}))
    m.feed(Sample(3 * MS, "other", {"ch0": 1000}))
    pose = m.pose()
    expected = np.zeros(68)
    expected[3 - 1] = 150                                        # open_jaw: 0.25 of 0..600
    expected[12 - 1] = 100                                       # raise_l_cornerlip: 0.5 of 0..200
    expected[13 - 1] = 50                                        # gain 0.5
    expected[49 - 1] = 15 * math.pi / 180 / AU                   # head yaw: 0.5 of -30..30 degrees, in AU
    expected[[25 - 1, 26 - 1]] = -10 * math.pi / 180 / AU        # both eyes' pitch, reversed range
    expected[19 - 1] = 900                                       # button held
    assert np.allclose(pose.fap, expected, rtol=0, atol=1e-9)
    assert pose.muscles == {"zygomatic_major_l": 1.0}           # two targets add up, clamped to 1
    assert pose.viseme is None and pose.expression is None
    assert pose.fap.shape == (68,) and pose.fap[:2].tolist() == [0, 0]


def test_the_pose_draws_on_the_runtime(runtime):
    doc = two_devices()
    doc["targets"] += [{"viseme": 10, "source": "box.ch0"}, {"expression": "joy", "source": "box.ch1"}]
    m = compile_mapping(doc)
    m.feed(Sample(1 * MS, "box", {"ch0": 600, "ch1": 400}))
    m.feed(Sample(2 * MS, "pad", {"X": -20, "A": 0}))
    pose = m.pose()
    vertices = runtime.deform_faps(pose.fap, viseme=pose.viseme, expression=pose.expression)
    assert vertices.shape == runtime.deform_faps().shape and np.isfinite(vertices).all()
    assert not np.allclose(vertices, runtime.deform_faps())


def test_combine_sum_max_last():
    def run(combine, feeds):
        doc = two_devices(fap="open_jaw", source=["box.ch0", "box.ch1"], combine=combine, range=[0, 100])
        m = compile_mapping(doc)
        for i, values in enumerate(feeds):
            m.feed(Sample((i + 1) * MS, "box", values))
        return fap_of(m.pose(), "open_jaw")

    assert run("sum", [{"ch0": 300, "ch1": 400}]) == pytest.approx(70)
    assert run("sum", [{"ch0": 800, "ch1": 700}]) == 100                  # clamped to the range
    assert run("max", [{"ch0": 300, "ch1": 400}]) == pytest.approx(40)
    assert run("last", [{"ch0": 300}, {"ch1": 400}, {"ch0": 100}]) == pytest.approx(10)
    assert run("last", [{"ch0": 300}, {"ch1": 400}]) == pytest.approx(40)
    assert run("last", [{"ch1": 900, "ch0": 200}]) == pytest.approx(20)   # the later value in the sample


def test_combine_max_of_bipolar_sources_takes_the_largest_deflection():
    doc = two_devices(head="yaw", source=["pad.X", "pad.Y"], combine="max", range=[-10, 10])
    doc["channels"]["pad.Y"] = {"range": "bipolar", "min": -100, "max": 100}
    m = compile_mapping(doc)
    m.feed(Sample(MS, "pad", {"X": 20, "Y": -60}))
    assert fap_of(m.pose(), 49) == pytest.approx(-6 * math.pi / 180 / AU)


def test_one_source_into_several_targets():
    m = compile_mapping(two_devices())
    m.feed(Sample(MS, "box", {"ch1": 1000}))
    pose = m.pose()
    assert fap_of(pose, 12) == 200 and fap_of(pose, 13) == 100 and pose.muscles["zygomatic_major_l"] == 1.0
    monitor = {c.name: c for c in m.channels()}
    assert monitor["box.ch1"].targets == ("fap 12 raise_l_cornerlip", "fap 13 raise_r_cornerlip",
                                          "muscle zygomatic_major_l")
    assert monitor["box.ch1"].raw == 1000 and monitor["box.ch1"].value == 1.0
    assert monitor["box.ch0"].raw is None and monitor["box.ch0"].value == 0.0


def test_momentary_and_toggle_buttons():
    doc = two_devices()
    held, toggled = "risorius_l", "risorius_r"
    doc["targets"] = [{"muscle": held, "source": "pad.A"}, {"muscle": toggled, "source": "pad.B"}]
    m = compile_mapping(doc)
    seen = []
    presses = [(0, 0), (1, 1), (1, 1), (0, 0.5), (0, 0.7), (1, 0.4), (1, 0.2), (0, 1), (0, 0)]
    for i, (a, b) in enumerate(presses):
        m.feed(Sample((i + 1) * MS, "pad", {"A": a, "B": b}))
        muscles = m.pose().muscles
        seen.append((muscles[held], muscles[toggled]))
    # A: 1 while held. B (threshold 0.6, release 0.3): the first press latches it on; 0.5, 0.7 and
    # 0.4 are one long press (never below the release level); 0.2 releases it, still on; the next
    # press turns it off.
    assert seen == [(0, 0), (1, 1), (1, 1), (0, 1), (0, 1), (1, 1), (1, 1), (0, 0), (0, 0)]


def test_visemes_and_expressions_become_fap_1_and_2():
    doc = two_devices()
    doc["channels"]["box.ch2"] = {"min": 0, "max": 1000}
    doc["targets"] = [{"viseme": 10, "source": "box.ch0"}, {"viseme": 3, "source": "box.ch1"},
                      {"expression": "joy", "source": "box.ch0"}, {"expression": 2, "source": "box.ch1"},
                      {"expression": "surprise", "source": "box.ch2"}]
    m = compile_mapping(doc)
    pose = m.pose()
    assert pose.viseme == (0, 0, 0.0) and pose.expression == (0, 0.0, 0, 0.0) and not pose.fap.any()
    m.feed(Sample(MS, "box", {"ch0": 1000, "ch1": 500, "ch2": 200}))
    pose = m.pose()
    shapes = high_level_faps()
    assert pose.viseme == (10, 0, 63.0)
    assert pose.expression == (1, 63.0, 2, 31.5)
    # the weaker viseme and the third expression are added as low-level FAPs
    expected = shapes["visemes"][3] * 0.5 + shapes["expressions"][6] * 0.2
    assert np.allclose(pose.fap, expected)


def test_viseme_order_flip_is_continuous(runtime):
    """Where two visemes swap which is strongest the face does not jump."""
    doc = two_devices()
    doc["targets"] = [{"viseme": 10, "source": "box.ch0"}, {"viseme": 14, "source": "box.ch1"}]
    m = compile_mapping(doc)
    engine = runtime.faps
    faces = []
    for i, (a, b) in enumerate([(500, 499), (500, 501)]):
        m.feed(Sample((i + 1) * MS, "box", {"ch0": a, "ch1": b}))
        p = m.pose()
        faces.append(engine.low_level(p.fap, p.viseme, p.expression))
    assert m.pose().viseme[0] == 14
    shapes = high_level_faps()["visemes"]
    step = np.abs(faces[0] - faces[1]).max()
    assert step < 0.003 * np.abs(shapes[10] - shapes[14]).max()  # a 1/1000 step of the weights moves the face as much


def test_pose_at_a_later_time_settles_held_inputs_without_changing_state():
    doc = two_devices()
    doc["channels"]["pad.A"]["rate_limit"] = 10       # a blink closes in 0.1 s
    doc["channels"]["box.ch0"]["smoothing"] = {"type": "exponential", "tau": 0.05}
    doc["targets"] = [{"muscle": "orbicularis_oculi_l", "source": "pad.A"},
                      {"muscle": "orbicularis_oris", "source": "box.ch0"}]
    m = compile_mapping(doc)
    m.feed(Sample(1000 * MS, "pad", {"A": 0}))
    m.feed(Sample(1000 * MS, "box", {"ch0": 0}))
    m.feed(Sample(1010 * MS, "pad", {"A": 1}))        # pressed: one message, then nothing
    m.feed(Sample(1010 * MS, "box", {"ch0": 1000}))
    assert m.pose().muscles["orbicularis_oculi_l"] == pytest.approx(0.1)
    later = m.pose(1060 * MS).muscles
    assert later["orbicularis_oculi_l"] == pytest.approx(0.6)
    assert later["orbicularis_oris"] == pytest.approx(1 - math.exp(-0.06 / 0.05), abs=1e-12)
    assert m.pose(2000 * MS).muscles["orbicularis_oculi_l"] == 1.0
    assert m.pose().muscles["orbicularis_oculi_l"] == pytest.approx(0.1)   # looking ahead kept nothing
    m.feed(Sample(1030 * MS, "pad", {"A": 1}))               # a sample older than the look-ahead
    assert m.pose().muscles["orbicularis_oculi_l"] == pytest.approx(0.3)


def test_garbage_values_are_counted_and_skipped():
    m = compile_mapping(two_devices())
    m.feed(Sample(MS, "box", {"ch0": 500}))
    m.feed(Sample(2 * MS, "box", {"ch0": float("nan"), "ch1": "x"}))
    m.feed(Sample(3 * MS, "box", {"ch0": None}))
    assert m.bad_values == 3
    assert fap_of(m.pose(), "open_jaw") == 300
    m.feed(Sample(4 * MS, "box", {"ch0": float("inf")}))
    assert fap_of(m.pose(), "open_jaw") == 600


def test_reset_returns_to_rest():
    m = compile_mapping(two_devices())
    m.feed(Sample(MS, "box", {"ch0": 500}))
    m.feed(Sample(MS, "pad", {"B": 1}))
    m.reset()
    assert not m.pose().fap.any() and all(c.raw is None for c in m.channels())


def test_device_options_are_folded_into_the_url():
    doc = with_(base(), ["devices", "box", "options"], {"baudrate": 115200, "rtscts": True})
    assert compile_mapping(doc).devices == {"box": "serial:///dev/ttyACM0?baudrate=115200&rtscts=true"}
    doc = with_(base(), ["devices", "box"], {"url": "serial:///dev/x?parity=N", "options": {"baudrate": 9600}})
    assert compile_mapping(doc).devices == {"box": "serial:///dev/x?parity=N&baudrate=9600"}


def test_load_mapping_from_a_file(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(two_devices()))
    m = load_mapping(path)
    assert m.devices == {"box": "serial:///dev/ttyACM0", "pad": "hid://046d:c21d"}
    path.write_text("devices: {}\n")
    with pytest.raises(MappingError, match=f"{path}:1: devices: expected a mapping"):
        load_mapping(path)


def test_throughput_and_latency_are_reported(capsys):
    """Measured, not asserted (timings depend on the machine): samples/s through feed on one
    core, and sample -> Pose latency."""
    m = load_mapping(MAPPINGS / "arduino_sliders.yaml")
    names = [f"ch{i}" for i in range(6)]
    n = 20_000
    samples = [Sample(i * MS, "box", {names[i % 6]: (i * 37) % 1024}) for i in range(n)]
    full = [Sample((n + i) * MS, "box", {c: (i * 37 + k) % 1024 for k, c in enumerate(names)}) for i in range(n // 4)]
    t0 = time.perf_counter()
    for s in samples:
        m.feed(s)
    one = n / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    for s in full:
        m.feed(s)
    six = len(full) / (time.perf_counter() - t0)
    latencies = []
    for i in range(3000):
        s = Sample((2 * n + i) * MS, "box", {names[i % 6]: (i * 53) % 1024})
        t0 = time.perf_counter_ns()
        m.feed(s)
        m.pose()
        latencies.append(time.perf_counter_ns() - t0)
    latencies.sort()
    with capsys.disabled():
        print(f"\nmapping arduino_sliders: feed {one:,.0f} samples/s (1 channel each), {six:,.0f} samples/s "
              f"(6 channels each); sample -> Pose median {latencies[len(latencies) // 2] / 1000:.1f} us, "
              f"p99 {latencies[int(len(latencies) * 0.99)] / 1000:.1f} us")
    assert one > 0 and six > 0


# -- snapshots: where a take starts --------------------------------------------------------------

SMOOTH = {"min": 0, "max": 1000, "smoothing": {"type": "one_euro", "min_cutoff": 1.0, "beta": 0.3}}


def _fed(doc, raws):
    m = compile_mapping(doc)
    for i, raw in enumerate(raws):
        m.feed(Sample(1_000 * MS + i * 7 * MS, "box", {"ch0": raw}))
    return m


@given(st.lists(st.floats(0, 1000), min_size=1, max_size=30), st.integers(0, 200))
@settings(max_examples=40, deadline=None)
def test_a_restored_snapshot_carries_on_exactly(raws, later_ms):
    live = _fed(base(**SMOOTH), raws)
    snapshot = json.loads(json.dumps(live.snapshot()))  # as a take's metadata keeps it
    restored = compile_mapping(base(**SMOOTH))
    restored.restore(snapshot)
    t = 2_000 * MS + later_ms * MS
    for m in (live, restored):
        m.feed(Sample(t, "box", {"ch0": 500.0}))
    assert restored.pose(t + 5 * MS).fap.tolist() == live.pose(t + 5 * MS).fap.tolist()


def test_a_snapshot_restored_into_a_differently_shaped_channel_starts_from_its_raw_input():
    live = _fed(base(**SMOOTH), [0, 900, 900, 900])
    other = compile_mapping(base(**{**SMOOTH, "max": 900}))
    other.restore(live.snapshot(), live)
    channel = other.channels()[0]
    assert channel.raw == 900 and channel.value == 1.0  # settled on the last input, shaped anew


def test_recentring_moves_a_sticks_rest_point_and_refuses_one_outside_its_range():
    doc = base(range="bipolar", min=0, centre=512, max=1023)
    m = compile_mapping(doc)
    m.feed(Sample(1_000 * MS, "box", {"ch0": 540.0}))     # a stick resting off centre: drift
    assert m.channels()[0].value > 0
    assert m.recentre(m.resting()) == {"box.ch0": 540.0}
    m.feed(Sample(1_010 * MS, "box", {"ch0": 540.0}))
    assert m.channels()[0].value == 0.0
    assert m.recentre({"box.ch0": 1023.0}) == {}           # the end of its travel cannot be rest


# -- issue 12: nothing a mapping says can make NaN, take unbounded time, or be silently ignored ----

@pytest.mark.parametrize(("channel", "key_path"), [
    ({"smoothing": {"type": "one_euro", "min_cutoff": 1e308}}, 'channels["box.ch0"].smoothing.min_cutoff'),
    ({"smoothing": {"type": "one_euro", "beta": 1e308}}, 'channels["box.ch0"].smoothing.beta'),
    ({"smoothing": {"type": "one_euro", "d_cutoff": 1e308}}, 'channels["box.ch0"].smoothing.d_cutoff'),
    ({"max": 1e-320}, 'channels["box.ch0"].max'),
    ({"min": -1e308}, 'channels["box.ch0"].min'),
    ({"range": "bipolar", "min": 0, "centre": 1e-300, "max": 1}, 'channels["box.ch0"].centre'),
    ({"smoothing": {"type": "exponential", "tau": 1e308}}, 'channels["box.ch0"].smoothing.tau'),
    ({"rate_limit": 1e308}, 'channels["box.ch0"].rate_limit'),
    ({"curve": {"type": "gamma", "gamma": 1e308}}, 'channels["box.ch0"].curve.gamma'),
    ({"button": {"mode": "toggle", "threshold": 1e308}}, 'channels["box.ch0"].button.threshold'),
])
def test_numbers_that_would_make_nan_or_inf_are_refused_at_load(channel, key_path):
    msg = str(error_of(base(**channel), "nan.yaml"))
    assert msg.startswith(f"nan.yaml: {key_path}: expected ") and "\n" not in msg


def test_a_target_range_or_gain_of_1e308_is_refused_and_every_accepted_mapping_stays_finite():
    for path, value in ((["targets", 0, "range"], [-1e308, 1e308]), (["targets", 0, "gain"], 1e308)):
        assert "targets[0]." in str(error_of(with_(base(), path, value)))
    m = compile_mapping(base(range="bipolar", min=-1e12, max=1e12,
                               smoothing={"type": "one_euro", "min_cutoff": 1000, "beta": 1000, "d_cutoff": 1000}))
    for t, raw in enumerate([0.0, 1e308, -1e308, float("inf"), 5.0, -float("inf"), 1e-300]):
        m.feed(Sample(t * 1_000_000, "box", {"ch0": raw}))
        assert np.isfinite(m.pose(t * 1_000_000 + 7).fap).all()
    assert m.held_values == 0


def test_integers_too_big_for_a_float_are_mapping_errors_not_overflow():
    for digits in (401, 5000):
        text = f"devices: {{box: {{url: 'serial:///dev/x'}}}}\nchannels: {{box.ch0: {{max: 1{'0' * digits}}}}}\n" \
               "targets: [{fap: 3, source: box.ch0, range: [0, 1]}]\n"
        msg = str(yaml_error(text, "big.yaml"))
        assert msg.startswith("big.yaml") and len(msg) < 300, msg
    assert "an integer of about 401 digits" in str(error_of(base(max=10 ** 400)))
    assert "devices.box.options.baudrate" in str(error_of(with_(base(), ["devices", "box", "options"],
                                                                {"baudrate": 10 ** 400})))


def test_billion_laughs_is_refused_at_once_in_bounded_memory():
    """Issue 12: 614 bytes, 10 alias levels; building repr() of the expanded value took 48 s and 3 GB."""
    import tracemalloc

    levels = "".join(f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
                     for p, c in zip("abcdefghi", "bcdefghij"))
    text = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + levels + "targets: *j\n"
    tracemalloc.start()
    try:
        msg = str(yaml_error(text, "lol.yaml"))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert msg == "lol.yaml: expected YAML aliases to add at most 10,000 values when expanded, found more " \
                  "(aliases nested in aliases)"
    assert peak < 20_000_000
    # a value that is big but within the budget is described in a few words, never printed whole
    wide = "a: &a [" + ", ".join(["lol"] * 60) + "]\nb: &b [" + ", ".join(["*a"] * 60) + "]\n" \
           "devices: {box: {url: 'serial:///dev/x'}}\nchannels: {box.ch0: {min: *b}}\n" \
           "targets: [{fap: 3, source: box.ch0, range: [0, 1]}]\n"
    msg = str(yaml_error(wide))
    assert "a list of 60 items" in msg and len(msg) < 400


def test_a_mapping_over_a_mebibyte_is_refused_unread(tmp_path):
    """40,000 targets (2.8 MB) held 195 MB and took a minute to check."""
    import tracemalloc

    path = tmp_path / "huge.yaml"
    path.write_text("targets:\n" + "  - {fap: open_jaw, source: box.ch0, range: [0, 1]}\n" * 40_000)
    tracemalloc.start()
    try:
        with pytest.raises(MappingError, match=r"huge.yaml: expected a mapping of at most 1 MiB"):
            load_mapping(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20_000_000


@pytest.mark.parametrize(("url", "option", "hint"), [
    ("midi://nanoKONTROL2", "chanel", "did you mean 'channel'?"),
    ("osc://127.0.0.1:39539", "chanel", "expected no options"),
    ("can://virtual/vcan0?signals=X:0x100:0:16", "bitrat", "did you mean 'bitrate'?"),
    ("serial:///dev/ttyACM0", "baudrat", "did you mean 'baudrate'?"),
    ("hid://046d:c21d", "usage_pag", "did you mean 'usage_page'?"),
    ("replay:///tmp/samples.jsonl", "sped", "did you mean 'speed'?"),
    ("sim://joystick", "protocl", "did you mean 'protocol'?"),
])
def test_device_options_are_checked_at_load_with_the_closest_name(url, option, hint):
    doc = with_(base(), ["devices", "box"], {"url": url, "options": {option: 1}})
    msg = str(error_of(doc, "opt.yaml"))
    assert msg.startswith(f"opt.yaml: devices.box.options.{option}: unknown option {option!r}") and hint in msg
    in_url = with_(base(), ["devices", "box"], {"url": url + ("&" if "?" in url else "?") + f"{option}=1"})
    assert f"devices.box.url: unknown option {option!r}" in str(error_of(in_url))


def test_readme_device_urls_load_in_a_mapping_and_unknown_schemes_do_not():
    for url in ("serial:loop://?protocol=slip", "serial:loop://?protocol=ascii&logging=debug",
                "serial:///dev/ttyACM0?baudrate=115200&protocol=cobs&checksum=none",
                "sim://joystick?protocol=ascii&checksum=nmea&rate=200"):
        assert compile_mapping(with_(base(), ["devices", "box", "url"], url)).devices["box"] == url
    assert "did you mean 'serial'?" in str(error_of(with_(base(), ["devices", "box", "url"], "seria:///dev/x")))


def test_mapping_error_is_a_puppet_error_and_a_value_error():
    from puppet.errors import PuppetError

    err = error_of(base(max=-5))
    assert isinstance(err, PuppetError) and isinstance(err, ValueError)


def test_a_nan_in_a_restored_state_holds_the_last_good_value_and_is_counted():
    m = compile_mapping(base(smoothing={"type": "one_euro"}), "held.yaml")
    m.feed(Sample(0, "box", {"ch0": 0.5}))
    assert m.pose(0).fap[2] == 300.0
    state = m.snapshot()
    state["channels"]["box.ch0"]["smoother"][1] = [float("nan"), 0.0]
    state["channels"]["box.ch0"]["value"] = float("nan")
    m.restore(state)
    m.feed(Sample(10_000_000, "box", {"ch0": 0.7}))
    assert m.pose(20_000_000).fap[2] == 300.0               # the value the face last showed
    assert m.held_values == 1 and m.held_problem.startswith("held.yaml: fap 3 open_jaw came out as NaN")
