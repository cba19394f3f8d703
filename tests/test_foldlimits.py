"""No FAP, expression or viseme folds the default face; the limits that see to it act at pose time
only, and a FAP still moves its own point by value x FAPU up to them (puppet.runtime.foldlimits)."""

from __future__ import annotations

import copy
import json
from importlib import resources

import numpy as np
import pytest

import puppet
from puppet.face.autorig import _lid_share
from puppet.face.rig import load_rig, save_rig
from puppet.fap.highlevel import high_level_faps
from puppet.fap.table import clamp_ranges, fap
from puppet.io.fapfile import read_fap, write_fap
from puppet.runtime.foldlimits import LIP_PAIRS, lid_faded, lid_unfaded
from puppet.runtime.lids import LID_PARTS
from puppet.runtime.musclesolver import folded_triangles


def _folds(face, vertices) -> int:
    return int(folded_triangles(face.vertices, vertices, np.asarray(face.triangles)).sum())


def _range_ends() -> list[tuple[int, float]]:
    low, high = clamp_ranges()
    return [(n, float(end)) for n in range(3, 69) for end in (low[n - 1], high[n - 1]) if np.isfinite(end) and end]


@pytest.mark.parametrize("number, end", _range_ends())
def test_no_fap_folds_the_face_at_either_end_of_its_range(runtime, face, number, end):
    """At both ends of every FAP's range the face shows the FAP's reach (with the other lip
    point of its pair following): no triangle folds (3,639 before the limits, 599 with every
    reach widened to the ARKit fits). A gaze FAP's reach caps the lid skin it carries, not the
    eyeball."""
    values = np.zeros(68)
    values[number - 1] = end
    assert _folds(face, runtime.deform_faps(values)) == 0


@pytest.mark.parametrize("kind, number", [(kind, n) for kind, top in (("expressions", 6), ("visemes", 14))
                                          for n in range(1, top + 1)])
def test_expressions_and_visemes_at_full_intensity_fold_nothing(runtime, face, kind, number):
    """Viseme 10 (A, the jaw at 520 MNS) folded 2 slivers below the lip corners before their quads
    were split along the other diagonal (``test_the_turned_quads_...``)."""
    pose = {"expression": (number, 63, 0, 0)} if kind == "expressions" else {"viseme": (number, 0, 63)}
    assert _folds(face, runtime.deform_faps(**pose)) == 0


def test_the_limits_leave_most_of_every_expression_and_viseme(runtime):
    """The reach caps range ends no face shows. Joy, sadness and disgust pass whole; the others
    keep at least 70% of each value (surprise's inner brows); the visemes at least 40% (the
    pursed lips of 13 and 14: the corners fold past 100 MW inward)."""
    shapes = high_level_faps()
    whole = 0
    for kind, least in (("expressions", 0.7), ("visemes", 0.4)):
        for number, values in shapes[kind].items():
            shown = runtime.faps.shown(values)
            moved = np.abs(values) > 0
            assert np.all(np.abs(shown[moved]) >= least * np.abs(values[moved]) - 1e-9), f"{kind} {number}"
            whole += bool(np.all(shown[moved] == values[moved]))
    assert whole >= 13  # of 22 (the empty expression 0 and viseme 0 included)


def test_a_value_beyond_the_reach_stays_in_the_file_and_is_capped_on_the_face(runtime, face, tmp_path):
    number = 35  # raise_l_o_eyebrow: -900 ENS lowers a brow by 4 cm
    low, _ = runtime.faps.reach[:, number - 1]
    assert -900 < low < 0
    frame = np.zeros(68)
    frame[number - 1] = -900
    path = tmp_path / "brow.fap"
    write_fap(path, frame[None], fps=25)
    read = read_fap(path).values[0]
    assert read[number - 1] == -900  # files are sacred
    at_reach = np.zeros(68)
    at_reach[number - 1] = low
    np.testing.assert_array_equal(runtime.deform_faps(read), runtime.deform_faps(at_reach))
    assert runtime.faps.encode(runtime.deform_faps(read))[number - 1] == pytest.approx(low, abs=1e-6)


@pytest.mark.parametrize("inner, outer", LIP_PAIRS)
def test_the_leading_lip_fap_moves_its_point_exactly_and_the_other_follows(runtime, face, inner, outer):
    """Each inner lip FAP and its outer twin (2.x / 8.x): the one with the larger value moves its
    own point by exactly value x FAPU, the other goes along just enough that their difference
    stays in the range that folds nothing; the encoder reads back what the face shows."""
    low, high, _, _ = runtime.rig.fap_follow[(inner, outer)]
    reach = runtime.faps.reach
    a, b = fap(inner), fap(outer)
    for lead, follower, value in ((a, b, min(2 * high, 0.9 * reach[1, inner - 1])),
                                  (b, a, max(2 * low, 0.9 * reach[0, outer - 1]))):
        values = np.zeros(68)
        values[lead.number - 1] = value
        moved = runtime.deform_faps(values) - face.vertices
        own = moved[face.feature_vertices[lead.feature_points[0]]] @ lead.axis
        assert own == pytest.approx(value * face.fapu[lead.unit], abs=1e-9)
        shown = runtime.faps.shown(values)
        gap = shown[inner - 1] - shown[outer - 1]
        assert low - 1e-9 <= gap <= high + 1e-9
        assert shown[follower.number - 1] != 0  # the other point went along
        np.testing.assert_allclose(runtime.faps.encode(runtime.deform_faps(values)), shown, atol=1e-6)


def test_lid_margins_turn_less_toward_the_still_eye_corners(runtime):
    margin = [p for p in runtime.rig.control_points if p.attach == "upper_lid_l" and p.name.startswith("upper_lid")]
    weights = sorted(p.attach_weight for p in margin)
    assert weights[0] < 0.2 and weights[-1] == 1.0
    path = np.c_[np.arange(17.0), np.zeros(17), np.zeros(17)]  # corner to corner, 16 equal steps
    share = _lid_share(path)
    assert share[0] == 0 and share[-1] == 0 and np.all(share[4:13] == 1)
    assert np.all(np.diff(share[:5]) > 0) and np.allclose(share, share[::-1])


@pytest.mark.parametrize(("number", "faded"), [(19, True), (20, True), (31, True), (21, False), (22, False), (25, False)])
def test_lid_margin_motions_fade_toward_the_corners_for_the_upper_lids_and_brows_not_the_lower_lids_or_gaze(
        runtime, number, faded):
    share = {p.name: p.attach_weight for p in runtime.rig.control_points if p.attach in LID_PARTS}
    motions = runtime.rig.fap_motions[number]
    corner = [name for name in motions if share.get(name, 1.0) < 0.5 and np.any(motions[name])]
    assert corner  # the FAP moves lid margin points near a corner
    after = lid_faded(runtime.rig)[number]
    for name in corner:
        np.testing.assert_allclose(after[name], motions[name] * (share[name] if faded else 1.0))


def test_unfading_undoes_the_fading_so_a_rig_calibrated_again_fades_its_lids_once(runtime):
    faded = copy.copy(runtime.rig)
    faded.fap_motions = lid_faded(runtime.rig)
    back = lid_unfaded(faded)
    for number, motions in runtime.rig.fap_motions.items():
        for name, motion in motions.items():
            np.testing.assert_allclose(back[number][name], motion, rtol=1e-12)


def test_a_rig_file_keeps_its_follow_pairs(tmp_path, runtime):
    rig = copy.deepcopy(runtime.rig)
    rig.fap_follow = {(6, 53): (-40.5, 10.0, -np.inf, np.inf), (12, 59): (-47.0, 42.0, -400.0, 700.0)}
    save_rig(rig, tmp_path / "face.rig")
    assert load_rig(tmp_path / "face.rig").fap_follow == rig.fap_follow


def test_a_rig_file_from_before_the_common_reach_loads_with_ranges_that_do_not_narrow(tmp_path, runtime):
    save_rig(runtime.rig, tmp_path / "face.rig")
    data = json.loads((tmp_path / "face.rig").read_text())
    data["fap_follow"] = {"12,59": [-47.0, 42.0]}
    (tmp_path / "face.rig").write_text(json.dumps(data))
    assert load_rig(tmp_path / "face.rig").fap_follow == {(12, 59): (-47.0, 42.0, -np.inf, np.inf)}


def test_the_lip_corner_alone_goes_as_far_as_a_smile_takes_it_and_folds_nothing(runtime, face):
    """Raised alone, the lip corner (2.4 / 2.5) used to fold the skin beside it from about
    490 MNS with its outer twin 145 MNS behind; the pair's range now narrows as the two rise together
    (puppet.runtime.follow), so the outer corner comes along and the corner reaches the end of its
    coding range (600 MNS, where the artist's smile fits put it), its own point moved exactly."""
    for number in (12, 13):
        values = np.zeros(68)
        values[number - 1] = 600.0
        shown = runtime.faps.shown(values)
        assert shown[number - 1] == 600.0
        assert 600.0 - shown[number + 46] < 60  # the outer corner came along
        moved = runtime.deform_faps(values) - face.vertices
        point = fap(number).feature_points[0]
        assert moved[face.feature_vertices[point]] @ fap(number).axis == pytest.approx(600.0 * face.fapu[fap(number).unit], abs=1e-9)
        assert _folds(face, runtime.deform_faps(values)) == 0


@pytest.mark.parametrize("number", [19, 20])
def test_a_full_blink_folds_no_eye_corner_and_still_closes(runtime, face, number):
    """The sliver guard (puppet.runtime.sliverguard) keeps the tiny triangles beside the still eye
    corner from turning over at a full blink, moving the skin there less than a millimetre from
    where DFFD put it; the lid's own point still drops by exactly value x IRISD, and half way
    closed the guard does nothing."""
    unguarded = _unguarded(runtime)
    for value, moved_at_most, unguarded_folds in ((1024.0, 0.0098, 9), (600.0, 0.0, 0)):
        values = np.zeros(68)
        values[number - 1] = value
        guarded, raw = runtime.deform_faps(values), unguarded.deform_faps(values)
        assert _folds(face, guarded) == 0
        assert _folds(face, raw) == unguarded_folds
        assert np.abs(guarded - raw).max() <= moved_at_most
        lid = face.feature_vertices["3.1" if number == 19 else "3.2"]
        drop = face.vertices[lid, 1] - guarded[lid, 1]
        assert drop == pytest.approx(value * face.fapu["IRISD0"], abs=1e-9)


def test_a_held_blink_reuses_the_sliver_guard_s_fix_and_shows_the_same_face(runtime, face):
    """The fix is a function of the watched vertices' positions: frame after frame a runtime that
    keeps it from the last frame (a blink held, then a brow moving under it, then the blink held
    again) shows exactly what a runtime deforming each pose afresh shows."""
    poses = [{19: 1024.0}, {19: 1024.0}, {19: 1024.0, 31: 80.0}, {19: 1024.0}, {19: 1024.0}, {19: 500.0}]
    for pose in poses:
        values = np.zeros(68)
        for number, value in pose.items():
            values[number - 1] = value
        fresh = puppet.Runtime(face, dtype=np.float64)
        np.testing.assert_array_equal(runtime.deform_faps(values), fresh.deform_faps(values))


BLINK = np.arange(600.0, 1081.0, 2.0)  # both upper lids, IRISD: past where the corners start to squeeze, to the range end


def _blink(value: float) -> np.ndarray:
    values = np.zeros(68)
    values[[18, 19]] = value
    return values


def test_a_moving_blink_is_foreseen_by_the_corrective_shapes(runtime):
    """Blended by the lids' turns, the corrective shapes leave the constraints nothing to fix at
    any blink: frame by frame they only check (fixing every frame of a moving blink had cost it
    the sweeps and their fallback)."""
    guard = runtime._slivers
    for value in BLINK:
        controls, rigid = runtime.fap_controls(_blink(value))
        out = runtime.deform(controls, rigid)
        guard._last = type(guard._last)()  # no fix kept from the frame before
        assert not guard(out, rigid), value


def test_the_eye_corners_follow_a_blink_smoothly(runtime, face):
    """Step by 2 IRISD, no watched vertex moves much farther than the lid's own steps take the skin
    (fixed frame by frame, the corner jumped 0.9 mm, 50 times a step, where the fallback took
    over), and the blink folds nothing anywhere."""
    frames = [runtime.deform_faps(_blink(value)) for value in BLINK]
    steps = np.linalg.norm(np.diff(np.array(frames), axis=0), axis=2).max(axis=1)
    assert steps.max() < 3.0 * np.median(steps), (steps.max(), np.median(steps), BLINK[1:][steps.argmax()])
    assert all(_folds(face, frame) == 0 for frame in frames[::10])


LIDS_AND_BROWS = {"left": ([18], [30, 32, 34]), "both": ([18, 19], [30, 31, 32, 33, 34, 35]),
                  "across": ([18], [31, 33, 35])}  # close_t_l/r_eyelid, raise_l/r_i/m/o_eyebrow (0-based)


@pytest.mark.parametrize("depth", [0.4, 1.0])
@pytest.mark.parametrize("sides", ["left", "both", "across"])
def test_a_blink_under_a_frown_is_foreseen_and_the_corners_follow_it_smoothly(runtime, sides, depth):
    """Brows lowered (``depth`` of the way to their reach on this face) while the lids close over
    the slider box's range: no watched vertex jumps (sampled for the lid alone, the outer corner
    jumped 1.0-1.7 mm in one 2 IRISD step, 68-115 times a step), and where the brows are the lid's
    own the shapes sampled with a frown leave the constraints little to fix (61-68% of these
    frames before). The other side's brows (the artists' brow motions reach across the face)
    squeeze the corner a little, which the constraints fix."""
    guard = runtime._slivers
    lids, brows = LIDS_AND_BROWS[sides]
    fixed, frames = 0, []
    for value in np.arange(400.0, 901.0, 2.0):
        values = np.zeros(68)
        values[lids] = value
        values[brows] = depth * runtime.faps.reach[0][brows]
        controls, rigid = runtime.fap_controls(values)
        out = runtime.deform(controls, rigid)
        guard._last = type(guard._last)()  # no fix kept from the frame before
        fixed += guard(out, rigid, controls)
        frames.append(out[guard.vertices])
    steps = np.linalg.norm(np.diff(np.array(frames), axis=0), axis=2).max(axis=1)
    assert steps.max() < 6.0 * np.median(steps), (steps.max(), np.median(steps))
    if sides != "across":
        assert fixed < 0.15 * len(frames)


def _unguarded(runtime):
    """A runtime of the same face and rig with no sliver guard."""
    other = copy.copy(runtime)
    other._slivers = None
    return other


def test_the_turned_quads_fold_split_makehuman_s_way_and_not_as_turned(runtime, face):
    """tools/builders/build_default_face.py splits the ``triangulation`` quads beside the lip corners along
    their other diagonal: of each mirror pair, MakeHuman's split folds a triangle with the jaw open
    wide (at its reach, 912 MNS), and the turned split folds none (nor at any other range end:
    ``test_no_fap_folds_...``)."""
    quads = json.loads((resources.files("puppet.data") / "default_face.json").read_text())["triangulation"]["turned_quads"]
    vertex_of = {int(s): v for v, s in enumerate(face.source_index) if s >= 0}
    quads = np.array([[vertex_of[s] for s in quad] for quad in quads])
    a, b, c, d = quads.T
    turned = np.concatenate([np.c_[b, c, d], np.c_[b, d, a]])
    makehuman = np.concatenate([np.c_[a, b, c], np.c_[a, c, d]])
    rows = {tuple(t) for t in np.asarray(face.triangles)}
    assert all(tuple(t) in rows for t in turned)
    values = np.zeros(68)
    values[2] = 1080
    wide = runtime.deform_faps(values)
    assert not folded_triangles(face.vertices, wide, turned).any()
    folds = folded_triangles(face.vertices, wide, makehuman).reshape(2, -1).any(axis=0)
    assert folds.reshape(-1, 2).any(axis=1).all()  # each mirror pair
