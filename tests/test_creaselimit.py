"""The cheeks' crease limit (``puppet.runtime.creaselimit``): lift_cheek lowered at pose time where
the skin under the eye would crease, whatever else the frame moves; nothing else changed."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import puppet
from puppet.fap.table import fap
from puppet.live.arkitroute import shipped_vectors
from puppet.runtime import creaselimit
from puppet.runtime.creaselimit import BOUND
from puppet.runtime.creases import largest_bend_near

CHEEKBONES = ("5.3", "5.4")
LIFTS = [40, 41]  # lift_l_cheek, lift_r_cheek (0-based)
SLACK = 0.5  # degrees: the limit's linear model leaves out the rigid parts' carried points


def _cheeks(face, runtime, values: np.ndarray) -> float:
    return largest_bend_near(face, runtime.deform_faps(values), CHEEKBONES, 0.08)


def _arkit(*names: str) -> np.ndarray:
    rows = shipped_vectors()["faps"]
    values = np.zeros(68)
    for name in names:
        for fap_name, value in rows[name].items():
            values[fap(fap_name).number - 1] += value
    return values


def test_a_live_smile_raises_the_cheeks_without_a_crease(face, runtime):
    """The ARKit route's smile (mouthSmile and cheekSquint at full, both sides) bent an edge under
    each eye by 122 degrees, cheekSquint alone by 48; the limit lowers lift_cheek until they bend no
    more than 20, and the cheeks still rise."""
    for names in (("mouthSmileLeft", "mouthSmileRight", "cheekSquintLeft", "cheekSquintRight"), ("cheekSquintLeft",)):
        values = _arkit(*names)
        shown = runtime.faps.shown(values)
        assert _cheeks(face, runtime, values) <= np.degrees(BOUND) + SLACK, names
        assert 0 < shown[40] < values[40], names
    smile = _arkit("mouthSmileLeft", "mouthSmileRight", "cheekSquintLeft", "cheekSquintRight")
    for point in CHEEKBONES:
        vertex = face.feature_vertices[point]
        assert runtime.deform_faps(smile)[vertex, 1] - face.vertices[vertex, 1] > 2 * face.fapu["ENS0"] * 20


def test_it_lowers_lift_cheek_no_further_than_the_crease_asks(face, runtime):
    """Lowered, the cheeks bend within a degree of the bound; below the crease nothing changes, and
    the face shows (and the encoder reads back) the lowered value."""
    values = np.zeros(68)
    values[LIFTS] = 60.0
    assert np.array_equal(runtime.faps.shown(values), values)
    values[LIFTS] = 200.0
    shown = runtime.faps.shown(values)
    assert 0 < shown[40] < 200 and values[40] == 200  # the caller's frame is not changed
    assert np.degrees(BOUND) - 1.0 < _cheeks(face, runtime, values) <= np.degrees(BOUND) + SLACK
    np.testing.assert_allclose(runtime.faps.encode(runtime.deform_faps(values))[LIFTS], shown[LIFTS], atol=1e-6)


def test_cheeks_that_do_not_crease_are_shown_as_they_are(runtime):
    """The expressions' cheeks (``build_high_level_faps`` keeps joy's within the bound; sadness lowers
    them 35 ENS) are shown as they are."""
    for number in range(1, 7):
        values = runtime.faps.low_level(np.zeros(68), expression=(number, 63, 0, 0))
        np.testing.assert_array_equal(runtime.faps.shown(values)[LIFTS], values[LIFTS])


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(lift=st.floats(-300, 300), smile=st.floats(0, 1), squint=st.floats(0, 1), jaw=st.floats(0, 1))
def test_lift_cheek_never_creases_the_cheek_more_than_the_rest_of_the_frame(face, runtime, lift, smile, squint, jaw):
    """Whatever the rest of the frame, the cheeks bend no more than the bound or than the frame
    bends them without lift_cheek."""
    values = smile * _arkit("mouthSmileLeft", "mouthSmileRight") + squint * _arkit("eyeSquintLeft", "eyeSquintRight")
    values += jaw * _arkit("jawOpen")
    values[LIFTS] += lift
    without = values.copy()
    without[LIFTS] = 0.0
    without_lift = _cheeks(face, runtime, without)
    assert _cheeks(face, runtime, values) <= max(np.degrees(BOUND), without_lift) + SLACK


def test_a_mesh_with_no_skin_edge_near_the_cheekbone_shows_lift_cheek_as_it_is(face, monkeypatch):
    monkeypatch.setattr(creaselimit, "NEAR", 0.0)
    values = np.zeros(68)
    values[LIFTS] = 200.0
    np.testing.assert_array_equal(puppet.Runtime(face).faps.shown(values)[LIFTS], values[LIFTS])
