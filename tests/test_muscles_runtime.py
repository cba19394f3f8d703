"""Muscles in the face runtime: the rig carries them, a pose contracts them (three modes, with FAPs),
a live take writes them as FAPs and replays byte for byte, a mapping names them or is refused."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from devices import State, open_device
from puppet import MappingError, load_mapping
from puppet.face.autorig import build_rig
from puppet.face.muscles import MUSCLE_NAMES
from puppet.face.rig import rig_from_dict, rig_to_dict
from puppet.fap.table import fap
from puppet.io.fapfile import read_fap
from puppet.io.takes import open_take
from puppet.live.retake import retake
from puppet.live.session import LiveSession
from puppet.runtime.musclesolver import EdgeConstraints, control_point_displacements, folded_triangles
from puppet.runtime.runtime import MUSCLE_MODES, Runtime
from puppet.runtime.skinsmoothing import skin_triangles

JOYSTICK = "sim://joystick?protocol=ascii&rate=200&channels=6"
SMILE_MAPPING = """\
devices:
  box: {url: "serial:///dev/ttyACM0?baudrate=115200", options: {protocol: ascii}}
channels:
  box.ch1: {min: 8, max: 1015}
  box.ch2: {min: 8, max: 1015}
targets:
  - {muscle: zygomatic_major_l, source: box.ch1}
  - {muscle: zygomatic_major_r, source: box.ch2}
idle: false   # the face shows the muscles alone: no blink or breath to tell apart
"""


def _moved(runtime, point: str, **pose) -> np.ndarray:
    """How far a feature point's vertex moves from rest in a pose."""
    v = runtime.face.feature_vertices[point]
    return runtime.deform_faps(**pose)[v] - runtime.rest[v]


# -- the rig carries the muscles ------------------------------------------------------------------

def test_the_default_face_carries_the_default_muscles(runtime):
    assert runtime.muscle_names == MUSCLE_NAMES
    assert len([n for n in MUSCLE_NAMES if n.endswith(("_l", "_r"))]) == 20  # 9 pairs + the eyes' sphincters


def test_muscles_round_trip_through_the_rig_file_and_a_version_1_file_loads_without(face):
    rig = build_rig(face)
    data = rig_to_dict(rig)
    again = rig_from_dict(data)
    assert [m.name for m in again.muscles] == list(MUSCLE_NAMES)
    np.testing.assert_array_equal(again.muscles[0].fixed, rig.muscles[0].fixed)
    old = {**data, "version": 1}
    del old["muscles"]
    assert rig_from_dict(old).muscles == []


def test_a_rig_without_muscles_refuses_a_contraction_by_name(face):
    rig = build_rig(face)
    rig.muscles = []
    bare = Runtime(face, rig)
    assert bare.muscle_names == ()
    np.testing.assert_array_equal(bare.deform_faps(muscles={"zygomatic_major_l": 0.0}), bare.rest)
    with pytest.raises(ValueError, match="unknown muscle 'zygomatic_major_l'"):
        bare.deform_faps(muscles={"zygomatic_major_l": 0.5})


# -- poses -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("mode", MUSCLE_MODES)
def test_zygomatic_major_pulls_the_mouth_corner_up_and_out(runtime, mode):
    d = _moved(runtime, "8.3", muscles={"zygomatic_major_l": 1.0}, mode=mode)
    assert d[0] > 0.005 and d[1] > 0.005  # +x is the face's left: out; +y: up
    assert np.linalg.norm(_moved(runtime, "8.4", muscles={"zygomatic_major_l": 1.0}, mode=mode)) < 1e-3


@pytest.mark.parametrize("mode", MUSCLE_MODES)
def test_the_pair_is_mirror_symmetric(runtime, mode):
    left = _moved(runtime, "8.3", muscles={"zygomatic_major_l": 1.0}, mode=mode)
    right = _moved(runtime, "8.4", muscles={"zygomatic_major_r": 1.0}, mode=mode)
    np.testing.assert_allclose(right * [-1, 1, 1], left, atol=0.15 * np.linalg.norm(left))


@pytest.mark.parametrize("mode", MUSCLE_MODES)
def test_muscles_and_faps_combine_in_one_pose(runtime, mode):
    faps = {"raise_l_i_eyebrow": 150, "raise_r_cornerlip": 100}
    muscles = {"zygomatic_major_l": 0.8, "frontalis_major_r": 0.6}
    both = runtime.deform_faps(faps, muscles=muscles, mode=mode) - runtime.rest
    apart = (runtime.deform_faps(faps) - runtime.rest) + (runtime.deform_faps(muscles=muscles, mode=mode) - runtime.rest)
    np.testing.assert_allclose(both, apart, atol=1e-9)  # no jaw: both drivers add up exactly
    opened = _moved(runtime, "8.3", fap={"open_jaw": 300}, muscles=muscles, mode=mode)
    assert opened[1] > _moved(runtime, "8.3", fap={"open_jaw": 300})[1] + 0.005


def test_no_muscle_contracting_is_the_fap_frame_exactly(runtime):
    faps = {"open_jaw": 250, "raise_l_cornerlip": 80}
    rest = dict.fromkeys(runtime.muscle_names, 0.0)
    np.testing.assert_array_equal(runtime.deform_faps(faps, muscles=rest), runtime.deform_faps(faps))


def test_an_unknown_muscle_or_mode_is_named(runtime):
    with pytest.raises(ValueError, match="did you mean 'zygomatic_major_l'"):
        runtime.deform_faps(muscles={"zygomatic_majr_l": 0.5})
    with pytest.raises(ValueError, match="muscle mode 'vertex'"):
        runtime.deform_faps(muscles={"zygomatic_major_l": 0.5}, mode="vertex")


@pytest.mark.parametrize("mode, folds", [("control", False), ("improved", False), ("classic", True)])
def test_contraction_10_folds_only_the_classic_skin(runtime, face, mode, folds):
    triangles = skin_triangles(face)
    for name in ("zygomatic_major_l", "zygomatic_major_r"):
        folded = folded_triangles(face.vertices, runtime.deform_faps(muscles={name: 10.0}, mode=mode), triangles)
        assert folded.any() == folds, (name, int(folded.sum()))


@pytest.mark.parametrize("mode", ["control", "improved"])
@pytest.mark.parametrize("name", MUSCLE_NAMES)
def test_no_muscle_folds_the_skin_at_contraction_10(runtime, face, name, mode):
    folded = folded_triangles(face.vertices, runtime.deform_faps(muscles={name: 10.0}, mode=mode), skin_triangles(face))
    assert not folded.any(), int(folded.sum())


@pytest.mark.parametrize("pose", [{name: c} for name in MUSCLE_NAMES for c in (0.5, 1.0)]
                         + [dict.fromkeys(MUSCLE_NAMES, 0.5)], ids=lambda p: "all_0.5" if len(p) > 1 else
                         "-".join(f"{k}={v}" for k, v in p.items()))
def test_normal_contractions_fold_nothing(runtime, face, pose):
    """A few muscles squeeze a triangle at contraction 1 (the risorius' at the lip corner, the
    orbicularis oculi's at the outer eye corner), all of them at 0.5 the lip corners'; the fold
    guard takes those back, so the face shows no fold."""
    assert not folded_triangles(face.vertices, runtime.deform_faps(muscles=pose), skin_triangles(face)).any()


def test_the_fold_guard_costs_nothing_at_ordinary_contraction(runtime, face):
    calm = runtime.deform_faps(muscles={"zygomatic_major_l": 1.0})
    assert not runtime._fold_guard.squeezed(calm[runtime._guard_vertices])  # so the guard left this frame as DFFD made it
    assert not folded_triangles(face.vertices, calm, skin_triangles(face)).any()


@pytest.mark.parametrize("name", MUSCLE_NAMES)
def test_no_muscle_at_half_squeezes_the_skin_before_the_guard(runtime, name):
    """Spread by DFFD alone, each muscle at 0.5 leaves every guarded corner above its floor: the
    lid margin's points near the still eye corners take their share of the lid's turn (moved in
    full, the orbicularis oculi turned the skin at the corners inside out, and every frame of a
    moving squint paid for the guard's sweeps)."""
    active = np.array([runtime.rig.point(n).position for n in runtime.control_points])
    share = control_point_displacements(runtime.rig.muscles, {name: 0.5}, active, runtime.muscle_shares)
    spread = runtime.deform(share)  # DFFD alone: the guard acts in deform_faps
    assert not runtime._fold_guard.squeezed(spread[runtime._guard_vertices].astype(float))


@pytest.fixture(scope="module")
def unwatched(face):
    """The default face's runtime without the rig's ``guarded`` triangles: the sliver guard's watch
    over the smile's lip corners would also hold the corners that the muscles and FAPs squeeze
    together, which the muscles' own guard does not define."""
    import copy

    rig = copy.copy(Runtime(face).rig)
    rig.guarded = np.zeros(0, dtype=np.int64)
    return Runtime(face, rig)


@pytest.mark.parametrize("contraction", [0.5, 1.0, 3.0, 10.0])
def test_the_guarded_muscles_are_the_fold_guard_of_their_share_on_the_whole_skin(unwatched, face, contraction):
    """The runtime spreads the FAPs' and the muscles' shares in one product and runs the fold guard
    on the guard's own vertices: that is, within float32 rounding, the definition -- the FAP frame
    plus the muscles' share spread by B's columns and fixed by edge constraints over every
    triangle the share reaches, on the whole mesh."""
    runtime = unwatched
    faps = {"raise_l_cornerlip": 120, "raise_b_midlip": -60}  # no rigid part moves: nothing is carried
    muscles = dict.fromkeys(runtime.muscle_names, contraction)
    k = len(runtime.control_points)
    active = np.array([runtime.rig.point(n).position for n in runtime.control_points])
    share = control_point_displacements(runtime.rig.muscles, muscles, active, runtime.muscle_shares)
    spread = runtime.B[:, :k].astype(float).tocsr()
    reached = np.diff(spread[:, np.flatnonzero(np.any(share != 0, axis=1))].tocsr().indptr) > 0
    movable = np.zeros(len(face.vertices), bool)
    for region in runtime.rig.regions:
        if region.kind == "dffd":
            movable[region.vertices] = True
    moved = spread @ share
    EdgeConstraints(face.vertices, face.triangles, movable, reached).relax(moved)
    expected = runtime.deform_faps(faps) + moved
    got = runtime.deform_faps(faps, muscles=muscles)
    height = np.ptp(face.vertices[:, 1])
    assert np.abs(got - expected).max() < 1e-5 * height


def test_a_guarded_frame_does_not_depend_on_the_frames_before(face):
    """The runtime keeps the muscles' share and the guard's correction for a held pose, and the
    guard a reference field for its check: any sequence of poses (held, moved away and back, the
    jaw moving under held muscles, the guard acting or not) draws every frame exactly as a fresh
    runtime draws it."""
    every = {c: dict.fromkeys(MUSCLE_NAMES, c) for c in (0.45, 0.5, 0.6)}
    poses = [every[0.5], every[0.5], every[0.6], {"zygomatic_major_l": 3.0}, every[0.5], {}, every[0.45], every[0.5]]
    jaws = [200, 350, 200, 200, 200, 200, 200, 200]
    kept = Runtime(face)
    for jaw, pose in zip(jaws, poses):
        np.testing.assert_array_equal(kept.deform_faps({"open_jaw": jaw}, muscles=pose),
                                      Runtime(face).deform_faps({"open_jaw": jaw}, muscles=pose))


# -- mappings ------------------------------------------------------------------------------------------

def test_a_mapping_naming_an_unknown_muscle_fails_with_the_closest_name(tmp_path):
    path = tmp_path / "smile.yaml"
    path.write_text(SMILE_MAPPING.replace("zygomatic_major_r", "zygomaticus_major_r"))
    with pytest.raises(MappingError) as err:
        load_mapping(path)
    message = str(err.value)
    assert "targets[1].muscle" in message and "zygomaticus_major_r" in message
    assert "did you mean 'zygomatic_major_r'?" in message


def test_the_slider_box_drives_smile_frown_and_brow_muscles():
    mapping = load_mapping(Path(__file__).resolve().parents[1] / "mappings" / "arduino_sliders.yaml")
    assert {"zygomatic_major_l", "zygomatic_major_r", "corrugator_supercilii_l", "frontalis_inner_r"} \
        <= set(mapping.muscle_names) <= set(MUSCLE_NAMES)


# -- a live take ----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def smile_take(face, tmp_path_factory):
    """A take of the simulated slider box through a mapping that drives only muscles."""
    root = tmp_path_factory.mktemp("smile")
    mapping = root / "smile.yaml"
    mapping.write_text(SMILE_MAPPING)
    session = LiveSession(mapping, face=Runtime(face), devices={"box": open_device(JOYSTICK, "box")},
                          record_root=root, fps=30)
    try:
        deadline = time.monotonic() + 5
        while not (all(s is State.OPEN for s in session.frame().states.values()) and session.samples_fed):
            assert time.monotonic() < deadline, "the simulated device never opened"
            time.sleep(0.01)
        session.start_recording()
        end = time.monotonic() + 0.6
        shown = []
        while time.monotonic() < end:
            f = session.frame()
            shown.append((dict(f.pose.muscles), f.vertices.copy()))
            time.sleep(0.01)
        return open_take(session.stop_recording()), shown, session.runtime
    finally:
        session.close()


def test_the_live_face_shows_the_muscles(smile_take):
    _, shown, runtime = smile_take
    muscles, vertices = max(shown, key=lambda s: s[0]["zygomatic_major_l"])
    assert muscles["zygomatic_major_l"] > 0.05
    np.testing.assert_allclose(vertices, runtime.deform_faps(muscles=muscles), atol=1e-6)


def test_a_muscle_take_is_written_as_faps_of_the_moved_feature_points(smile_take):
    take, _, _ = smile_take
    values = read_fap(take.fap_path).values
    corner = [fap(n).number - 1 for n in ("stretch_l_cornerlip_o", "raise_l_cornerlip_o",
                                         "stretch_r_cornerlip_o", "raise_r_cornerlip_o")]
    assert len(values) >= 10
    assert (np.abs(values[:, corner]) > 0).any(axis=0).all()
    assert (values[:, [fap(n).number - 1 for n in ("raise_l_cornerlip_o", "raise_r_cornerlip_o")]] >= 0).all()
    assert not values[:, [fap("open_jaw").number - 1, fap("head_yaw").number - 1]].any()


def test_a_muscle_take_replays_identically(smile_take, tmp_path):
    take, _, _ = smile_take
    result = retake(take, tmp_path / "again.fap")
    assert result.identical and result.frames == take.meta["frames"]
