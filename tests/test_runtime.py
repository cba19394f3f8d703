"""The default face's rig deforms as the paper's weighted DFFD says it must."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from puppet.face import rigid
from puppet.face.default import load_default_rig
from puppet.face.load import load_face
from puppet.face.rig import load_rig, save_rig
from puppet.runtime.musclesolver import folded_triangles
from puppet.runtime.runtime import Runtime
from puppet.runtime.sibson import sibson_coordinates


def _displace(rt: Runtime, moves: dict[str, tuple[float, float, float]]) -> np.ndarray:
    d = np.zeros((len(rt.control_points), 3))
    for name, move in moves.items():
        d[rt.control_points.index(name)] = move
    return d


def _region(rt: Runtime, name: str) -> np.ndarray:
    return rt.rig.region(name).vertices


def test_zero_displacement_gives_the_neutral_mesh_exactly(runtime, face):
    out = runtime.deform(np.zeros((len(runtime.control_points), 3)))
    assert np.array_equal(out, face.vertices)


def test_a_direct_control_point_moves_its_vertex_by_exactly_its_displacement(runtime, face):
    for name in ("8.3", "4.3", "9.3", "5.1", "2.10"):
        point = runtime.rig.point(name)
        assert point.direct
        move = np.array([0.011, -0.007, 0.005])
        out = runtime.deform(_displace(runtime, {name: move}))
        np.testing.assert_allclose(out[point.vertex] - face.vertices[point.vertex], move, atol=1e-12)


def test_translating_every_control_point_of_a_region_translates_the_region(face):
    rig = load_default_rig()
    nose = rig.region("nose")
    index = rig.point_index()
    for name in nose.control_points:
        rig.control_points[index[name]].role = "active"
        rig.control_points[index[name]].driver = None
    rt = Runtime(face, rig, dtype=np.float64, cache=False)
    move = np.array([0.01, 0.02, -0.015])
    out = rt.deform(_displace(rt, dict.fromkeys(nose.control_points, move)))
    np.testing.assert_allclose(out[nose.vertices] - face.vertices[nose.vertices], np.broadcast_to(move, (len(nose.vertices), 3)), atol=1e-12)


def test_moving_the_nose_moves_no_forehead_vertex(runtime, face):
    out = runtime.deform(_displace(runtime, {"9.3": (0.0, 0.03, 0.02), "9.1": (0.02, 0, 0), "9.2": (-0.02, 0, 0)}))
    moved = np.linalg.norm(out - face.vertices, axis=1) > 0
    assert moved[_region(runtime, "nose")].any()
    for other in ("forehead", "cheek_l", "cheek_r", "upper_mouth", "lower_mouth", "rest"):
        assert not moved[_region(runtime, other)].any(), other


def test_passive_points_carry_motion_across_their_border_one_way(face):
    from puppet.face.autorig import build_rig

    runtime = Runtime(face, build_rig(face, grid=False, calibrated=False), dtype=np.float64)  # no grid point in the way
    lower_lip = runtime.deform(_displace(runtime, {"8.2": (0, -0.04, 0), "8.7": (0, -0.03, 0), "8.8": (0, -0.03, 0)}))
    moved = np.linalg.norm(lower_lip - face.vertices, axis=1) > 1e-9
    assert moved[_region(runtime, "cheek_l")].any() and moved[_region(runtime, "cheek_r")].any()
    assert not moved[_region(runtime, "forehead")].any()
    cheek = runtime.deform(_displace(runtime, {"5.1": (0.02, 0, 0.02)}))
    moved = np.linalg.norm(cheek - face.vertices, axis=1) > 0
    assert moved[_region(runtime, "cheek_l")].any()
    for other in ("upper_mouth", "lower_mouth", "nose", "forehead", "cheek_r"):
        assert not moved[_region(runtime, other)].any(), other


def test_rigid_parts_keep_their_distances(runtime, face):
    jaw = runtime.rig.rigid_parts["jaw"]
    eye = runtime.rig.rigid_parts["eye_l"]
    motions = {
        "jaw": rigid.about(jaw.pivot, rigid.rotation(jaw.axis, np.radians(15))),
        "eye_l": rigid.about(eye.pivot, rigid.rotation((0, 1, 0), np.radians(20))),
    }
    out = runtime.deform(np.zeros((len(runtime.control_points), 3)), motions)
    for region in ("lower_teeth", "eyeball_l", "tongue"):
        v = _region(runtime, region)
        before = np.linalg.norm(face.vertices[v][:, None] - face.vertices[v][None], axis=2)
        after = np.linalg.norm(out[v][:, None] - out[v][None], axis=2)
        np.testing.assert_allclose(after, before, atol=1e-9)
        assert np.abs(out[v] - face.vertices[v]).max() > 1e-3


def test_the_jaw_opens_the_mouth_through_control_points(runtime, face):
    jaw = runtime.rig.rigid_parts["jaw"]
    out = runtime.deform(np.zeros((len(runtime.control_points), 3)),
                         {"jaw": rigid.about(jaw.pivot, rigid.rotation(jaw.axis, np.radians(12)))})
    chin = face.feature_vertices["2.1"]
    lower_lip = face.feature_vertices["8.2"]
    upper_lip = face.feature_vertices["8.1"]
    assert out[chin, 1] < face.vertices[chin, 1] - 0.05
    assert out[lower_lip, 1] < face.vertices[lower_lip, 1] - 0.05
    assert abs(out[upper_lip, 1] - face.vertices[upper_lip, 1]) < 0.01


def test_head_rotation_turns_the_head_and_leaves_the_neck_base(runtime, face):
    head = runtime.rig.rigid_parts["head"]
    motion = rigid.about(head.pivot, rigid.rotation((0, 1, 0), np.radians(30)))
    out = runtime.deform(np.zeros((len(runtime.control_points), 3)), {"head": motion})
    nose = face.feature_vertices["9.3"]
    np.testing.assert_allclose(out[nose], rigid.apply(motion, face.vertices[nose:nose + 1])[0], atol=1e-12)
    base = face.vertices[:, 1] < head.neck[0]
    assert base.any() and np.array_equal(out[base], face.vertices[base])


def test_realtime_recompute_equals_a_fresh_precompute(face):
    rt = Runtime(face, mode="realtime", threshold=0.01, dtype=np.float64, cache=False)
    rest_sites = rt.deformers["upper_mouth"].sites.copy()
    d = _displace(rt, {"8.3": (0.03, 0.02, 0), "2.4": (0.03, 0.02, 0), "4.3": (0, 0.03, 0)})
    rt.deform(d)
    assert not np.allclose(rt.deformers["upper_mouth"].sites, rest_sites), "no rebase happened"
    for region in ("upper_mouth", "forehead", "cheek_l"):
        deformer = rt.deformers[region]
        fresh = sibson_coordinates(deformer.queries, np.vstack([deformer.sites, deformer.box]))
        np.testing.assert_allclose(deformer.sibson.toarray(), fresh.toarray(), atol=1e-12)


def test_realtime_matches_precomputed_below_the_threshold(face):
    rt = Runtime(face, mode="realtime", threshold=1.0, dtype=np.float64)
    exact = Runtime(face, prune=0, dtype=np.float64)
    d = _displace(rt, {"8.3": (0.02, 0.01, 0), "8.2": (0, -0.02, 0), "4.3": (0, 0.02, 0)})
    np.testing.assert_allclose(rt.deform(d), exact.deform(d), atol=1e-12)


def test_pruning_moves_no_vertex_by_more_than_a_hair(face, runtime):
    exact = Runtime(face, prune=0, dtype=np.float64)
    assert runtime.B.nnz < 0.8 * exact.B.nnz
    rng = np.random.default_rng(1)
    d = rng.normal(scale=0.02, size=(len(runtime.control_points), 3))
    error = np.linalg.norm(runtime.deform(d) - exact.deform(d), axis=1).max()
    assert error < 0.01 * np.abs(d).max()


def test_control_point_motions_deform_as_given_and_a_pose_is_guarded(face, runtime):
    """``deform`` is the DFFD product of the control points as given: a random field that
    squeezes the eye corners stays as it is. A pose (``deform_faps``) gets the sliver guard: a
    full blink, which deform leaves with its slivers, folds nothing."""
    rng = np.random.default_rng(1)
    d = rng.normal(scale=0.02, size=(len(runtime.control_points), 3))
    unguarded = copy.copy(runtime)
    unguarded._slivers = None
    np.testing.assert_array_equal(runtime.deform(d), unguarded.deform(d))
    controls, motions = runtime.fap_controls({"close_t_l_eyelid": 1024})
    triangles = np.asarray(face.triangles)
    assert folded_triangles(face.vertices, runtime.deform(controls, motions), triangles).sum() > 0
    assert folded_triangles(face.vertices, runtime.deform_faps({"close_t_l_eyelid": 1024}), triangles).sum() == 0


def test_rig_file_round_trip(runtime, tmp_path):
    path = tmp_path / "face.rig.json"
    save_rig(runtime.rig, path)
    again = load_rig(path)
    assert [p.name for p in again.control_points] == [p.name for p in runtime.rig.control_points]
    for a, b in zip(again.regions, runtime.rig.regions):
        assert a.name == b.name and np.array_equal(a.vertices, b.vertices)


@pytest.mark.parametrize("field", ["guarded", "smoothed"])
def test_a_rig_s_vertex_lists_round_trip_and_are_checked(runtime, tmp_path, field):
    """The vertices a rig's fold guard watches, and those it smooths, are saved as runs and read
    back; a rig with none writes no key; an index past the face is refused by name."""
    import copy

    from puppet.face.rig import RigError, rig_to_dict

    rig = copy.copy(runtime.rig)
    setattr(rig, field, np.zeros(0, dtype=np.int64))
    assert field not in rig_to_dict(rig)
    setattr(rig, field, np.array([5, 6, 7, 40, 41]))
    save_rig(rig, tmp_path / "listed.rig")
    assert getattr(load_rig(tmp_path / "listed.rig"), field).tolist() == [5, 6, 7, 40, 41]
    data = rig_to_dict(rig)
    data[field] = [[0, rig.n_vertices]]
    (tmp_path / "bad.rig").write_text(json.dumps(data))
    with pytest.raises(RigError, match=rf"bad\.rig: {field}: vertex indices must lie in 0\.\."):
        load_rig(tmp_path / "bad.rig")


def test_cached_coefficients_load_the_same_rig_without_computing(face, tmp_path, monkeypatch):
    monkeypatch.setenv("FACEPUPPET_CACHE", str(tmp_path))
    first = Runtime(face, dtype=np.float64)
    assert list(tmp_path.glob("*.npz"))

    def no_sibson(*args, **kwargs):
        raise AssertionError("Sibson coordinates were computed although they are cached")

    monkeypatch.setattr("puppet.runtime.dffd.sibson_coordinates", no_sibson)
    second = Runtime(face, dtype=np.float64)
    assert (first.B != second.B).nnz == 0


def test_a_damaged_cache_file_is_recomputed(face, tmp_path, monkeypatch):
    monkeypatch.setenv("FACEPUPPET_CACHE", str(tmp_path))
    Runtime(face)
    (cached,) = tmp_path.glob("*.npz")
    for damage in (b"", cached.read_bytes()[:500]):
        cached.write_bytes(damage)
        rt = Runtime(face, dtype=np.float64)
        assert np.array_equal(rt.deform(np.zeros((len(rt.control_points), 3))), face.vertices)
        assert cached.stat().st_size > 1000, "the damaged file was not rewritten"


def test_a_non_contiguous_output_buffer_is_refused(runtime):
    d = np.zeros((len(runtime.control_points), 3))
    with pytest.raises(ValueError, match="C-contiguous"):
        runtime.deform(d, out=np.empty((len(runtime.rest), 4))[:, :3])


def test_a_malformed_rigid_motion_is_named(runtime):
    d = np.zeros((len(runtime.control_points), 3))
    with pytest.raises(ValueError, match="'jaw' must be a 3x4"):
        runtime.deform(d, {"jaw": np.eye(4)})
    with pytest.raises(ValueError, match="unknown rigid motions \\['neck'\\]"):
        runtime.deform(d, {"neck": np.eye(3, 4)})


def test_realtime_mode_survives_points_dragged_onto_each_other(face):
    rt = Runtime(face, mode="realtime", threshold=0.01, dtype=np.float64, cache=False)
    onto = face.feature_points["8.1"] - face.feature_points["8.3"]
    with pytest.warns(UserWarning, match="rebase skipped"):
        out = rt.deform(_displace(rt, {"8.3": onto}))
    assert np.isfinite(out).all()


def test_normals_follow_the_deformation(runtime, face):
    parts = runtime.rig.rigid_parts
    motions = {name: rigid.about(parts[name].pivot, rigid.rotation(axis, np.radians(angle)))
               for name, axis, angle in (("jaw", parts["jaw"].axis, 15), ("eye_l", (0, 1, 0), 20),
                                         ("upper_lid_r", (1, 0, 0), 20), ("head", (0.3, 1, 0.1), 25))}
    d = _displace(runtime, {"8.3": (0.02, 0.02, 0), "4.4": (0, 0.03, 0)})
    v, n = runtime.deform_with_normals(d, motions)
    from puppet.runtime.normals import VertexNormals

    np.testing.assert_allclose(n, VertexNormals(face.triangles, len(face.vertices))(v), atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)
    into = np.zeros((len(v), 6), n.dtype)  # a caller's strided buffer gets the same normals
    runtime.normals(v, motions, out=into[:, 1:4])
    np.testing.assert_array_equal(into[:, 1:4], n)


def test_the_shipped_rig_is_what_autorig_builds_today(face):
    from puppet.face.autorig import build_rig
    from puppet.face.rig import rig_to_dict

    shipped = rig_to_dict(load_default_rig())
    built = json.loads(json.dumps(rig_to_dict(build_rig(face, calibrated=False))))
    for calibrated in ("fap_motions", "fap_reach", "fap_follow"):  # calibration and fold limits add them
        del shipped[calibrated], built[calibrated]
    del shipped["guarded"]  # and the triangles the shipped poses fold, which the fold guard holds
    assert shipped == built, "run tools/builders/build_default_rig.py"


def test_hybrid_eyelid_turns_its_margin_about_the_eyeball_and_the_lid_follows(runtime, face):
    eye = runtime.rig.rigid_parts["upper_lid_l"]
    close = rigid.about(eye.pivot, rigid.rotation(eye.axis, np.radians(25)))
    out = runtime.deform(np.zeros((len(runtime.control_points), 3)), {"upper_lid_l": close})
    lid = face.feature_vertices["3.1"]
    centre = face.pivots["eye_l"]
    assert out[lid, 1] < face.vertices[lid, 1] - 0.03
    assert np.linalg.norm(out[lid] - centre) == pytest.approx(np.linalg.norm(face.vertices[lid] - centre))
    moved = np.linalg.norm(out - face.vertices, axis=1) > 1e-9
    assert moved.sum() > 20
    assert not moved[_region(runtime, "eyeball_l")].any()
    motion = np.linalg.norm(out - face.vertices, axis=1)
    right = face.vertices[:, 0] < 0
    assert motion[right].max() < 0.02 * motion.max(), "closing the left lid moved the right side"


def test_a_face_without_feature_points_cannot_be_rigged_and_says_which(tmp_path):
    from puppet.face.rig import RigError

    path = tmp_path / "tet.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    with pytest.raises(RigError, match=r"face 'tet': cannot rig without feature points \[.*'2\.1'"):
        Runtime(load_face(path))


def test_a_bad_rig_file_names_the_file_and_the_problem(tmp_path, runtime):
    from puppet.face.rig import RigError, rig_to_dict

    data = rig_to_dict(runtime.rig)
    data["control_points"][0]["role"] = "dancing"
    path = tmp_path / "bad.rig.json"
    path.write_text(json.dumps(data))
    with pytest.raises(RigError, match=r"bad\.rig\.json: control point .*role 'dancing'"):
        load_rig(path)
    path.write_text("{ not json")
    with pytest.raises(RigError, match=r"bad\.rig\.json:1: not valid JSON"):
        load_rig(path)
