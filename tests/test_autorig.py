"""The auto-rig from landmarks: deterministic, regions partition the mesh, rotation and scale do
not change the motion, landmark errors are named, iBUG 68 works (puppet.face.landmarks, puppet.face.autorig)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.bench.assets import shared_assets
from puppet.cli import main
from puppet.face.autorig import _loop_path_via, _spread_out, build_rig
from puppet.face.landmarks import FDP_NEEDED, FDP_NEEDED_WHAT, IBUG_FDP, LandmarkError, read_landmarks
from puppet.face.load import load_face
from puppet.face.meshfile import write_bare_obj
from puppet.face.rig import rig_to_dict
from puppet.photo.build import MEDIAPIPE_FDP
from puppet.runtime.runtime import Runtime
from tools.figures.rig_faces import ict_inputs, mediapipe_inputs


def _rotation(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


@pytest.fixture(scope="module")
def default():
    return load_face()


def _covered_once(face, rig):
    count = np.zeros(len(face.vertices), dtype=int)
    for region in rig.regions:
        np.add.at(count, region.vertices, 1)
    return bool((count[face.parts["skin"]] == 1).all() and (count == 1).all())


def test_the_auto_rig_is_deterministic(default):
    assert rig_to_dict(build_rig(default)) == rig_to_dict(build_rig(load_face()))


def test_an_opening_jaw_drops_the_lower_lip_s_sides_less_than_its_middle(default):
    """The jaw's share tapers across the lower lip to the corners' half, so at open_jaw 400 its
    sides (8.7, 8.8) drop 0.72 as far as its middle (8.2), as in the artist's jawOpen (0.76); they
    dropped 0.95 as far, and every open mouth's fit pulled the middle down past them into a V."""
    runtime = Runtime(default, build_rig(default, calibrated=False))
    drop = runtime.deform_faps(fap={"open_jaw": 400.0}) - runtime.deform_faps()
    middle = drop[default.feature_vertices["8.2"], 1]
    for side in ("8.7", "8.8"):
        assert 0.6 < drop[default.feature_vertices[side], 1] / middle < 0.85


def test_regions_cover_every_skin_vertex_once(default):
    assert _covered_once(default, build_rig(default))


@pytest.mark.parametrize("which", ["ict", "mediapipe"])
def test_shared_faces_rig_and_regions_cover_them(which):
    inputs = (ict_inputs if which == "ict" else mediapipe_inputs)(shared_assets())
    if inputs is None:
        pytest.skip(f"{which} assets absent")
    mesh, landmarks = inputs
    face = load_face(mesh, landmarks=landmarks)
    rig = build_rig(face)
    assert _covered_once(face, rig)
    assert rig_to_dict(rig) == rig_to_dict(build_rig(load_face(mesh, landmarks=landmarks)))
    assert {"forehead", "nose", "upper_mouth", "lower_mouth", "cheek_l", "cheek_r"} <= {r.name for r in rig.regions}


def test_a_scaled_rotated_copy_moves_the_same_scaled_and_rotated(default, tmp_path):
    """Up to a ten-thousandth of the largest motion: the sliver guard's corrective shapes are its
    fixes sampled at build time, whose sweeps and fallback branch on roundoff (here a 0.2% frown
    the joy expression reads as blends in a shape that differs between the copies by 0.07%; with
    the calibration's feature-point motions carried over, two lip vertices differ by 5.6e-5 of the
    largest motion, the rest by 1.6e-7 as without the guard)."""
    R = _rotation((0.3, 1.0, -0.4), 0.7)
    shift = np.array([2.0, -1.0, 0.5])
    landmarks = dict(default.feature_vertices)
    a = load_face(write_bare_obj(tmp_path / "a.obj", default.vertices, default.triangles), landmarks=landmarks)
    b = load_face(write_bare_obj(tmp_path / "b.obj", 1.7 * default.vertices @ R.T + shift, default.triangles),
                  landmarks=landmarks)
    rig_a, rig_b = build_rig(a), build_rig(b)
    assert [(r.name, r.vertices.tolist()) for r in rig_a.regions] == [(r.name, r.vertices.tolist()) for r in rig_b.regions]
    fap = {3: 400, 31: 200, 53: 150, 19: 300}
    moves = []
    for face, rig in ((a, rig_a), (b, rig_b)):
        runtime = Runtime(face, rig, cache=False, dtype=np.float64, prune=0)
        d = runtime.deform_faps(fap, expression=(1, 40, 0, 0)) - face.vertices
        moves.append(d @ face.placement[:, :3])  # back into the file's own axes
    assert np.abs(moves[0]).max() > 0.01
    np.testing.assert_allclose(moves[1], 1.7 * moves[0] @ R.T, atol=1e-4 * np.abs(moves[0]).max())


@pytest.mark.parametrize("landmarks, message", [
    ({"2.1": 10 ** 7}, "outside"),
    ({"2.1": 1.5}, "integer"),
    ({"12.1": 3}, "unknown FDP"),
    ({"2.15": 3}, "unknown FDP"),
    (list(range(67)), "68 iBUG"),
    ({"2.1": 3}, "needed"),
    ("not landmarks", "expected an object"),
])
def test_landmark_errors_are_clear(default, tmp_path, landmarks, message):
    mesh = write_bare_obj(tmp_path / "m.obj", default.vertices, default.triangles)
    with pytest.raises(LandmarkError, match=message):
        source = tmp_path / "l.json"
        source.write_text(json.dumps(landmarks))
        load_face(mesh, landmarks=landmarks if isinstance(landmarks, list) else source)


def test_a_landmark_file_like_ict_facekits_gives_its_68_ibug_points_from_its_key(tmp_path):
    """ICT-FaceKit ships ``vertex_indices.json``: an object of lists, the 68 iBUG landmark
    vertices under ``idx_to_landmark_verts``. That list is read; two such lists are named."""
    ibug = list(range(100, 168))
    path = tmp_path / "vertex_indices.json"
    path.write_text(json.dumps({"expressions": ["browDown_L"] * 53, "idx_to_landmark_verts": ibug,
                                "idx_to_rigid_landmark_idx": [0, 36, 39]}))
    assert read_landmarks(path, 500) == ibug
    path.write_text(json.dumps({"a": ibug, "b": ibug}))
    with pytest.raises(LandmarkError, match="several keys hold 68 vertex indices \\('a', 'b'\\)"):
        read_landmarks(path, 500)
    path.write_text(json.dumps({"expressions": ["x"], "fitting": [1, 2]}))
    with pytest.raises(LandmarkError, match="unknown FDP id.*68 iBUG vertex indices, as a list or under one key"):
        read_landmarks(path, 500)


def test_a_missing_needed_feature_point_is_named_with_what_it_is(default, tmp_path):
    """Issue 38: a user's landmarks without the brows rig (those are placed); without a lip point
    the one line names the file, the point and where it goes, and how many rig needs."""
    mesh = write_bare_obj(tmp_path / "m.obj", default.vertices, default.triangles)
    marks = {f: v for f, v in default.feature_vertices.items() if not f.startswith("4.") and f not in ("8.6", "3.2")}
    (tmp_path / "points.json").write_text(json.dumps(marks))
    with pytest.raises(LandmarkError) as err:
        load_face(mesh, landmarks=tmp_path / "points.json")
    text = str(err.value)
    assert str(tmp_path / "points.json") in text and "2 needed feature points missing" in text, text
    assert f"8.6 ({FDP_NEEDED_WHAT['8.6']})" in text and f"3.2 ({FDP_NEEDED_WHAT['3.2']})" in text, text
    assert f"these {len(FDP_NEEDED)}" in text and "\n" not in text, text
    assert set(FDP_NEEDED_WHAT) == set(FDP_NEEDED)


def test_the_nose_tip_on_another_feature_point_names_both_and_what_to_do(default, tmp_path, capsys):
    """Issue 38: the nose tip put on the nose bone's vertex was 'duplicate sites: 1 pairs, e.g.
    indices 3 and 4'; now the feature points are named, and what to do with them."""
    mesh = write_bare_obj(tmp_path / "m.obj", default.vertices, default.triangles)
    marks = dict(default.feature_vertices) | {"9.3": int(default.feature_vertices["9.1"])}
    (tmp_path / "points.json").write_text(json.dumps(marks))
    assert main(["rig", str(mesh), "--landmarks", str(tmp_path / "points.json"), "-o", str(tmp_path / "me")]) != 0
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "feature points 9.1 and 9.3 fall on the same place" in line and "pick-landmarks" in line, line


def test_the_mediapipe_face_rigs_from_the_project_s_own_table_without_the_brows(tmp_path, capsys):
    """Issue 38: MediaPipe's canonical mesh with landmarks written from ``MEDIAPIPE_FDP`` less the
    brow points 4.x ended in ``LinAlgError: Singular matrix`` (two placed points on one vertex made
    the feature warp's system singular); it rigs."""
    mesh = shared_assets() / "mediapipe_face" / "mediapipe_canonical_face_model.obj"
    if not mesh.is_file():
        pytest.skip("the MediaPipe canonical face is not in ../shared")
    marks = {fdp: index for index, fdp in MEDIAPIPE_FDP.items() if not fdp.startswith("4.")}
    (tmp_path / "points.json").write_text(json.dumps(marks))
    assert main(["rig", str(mesh), "--landmarks", str(tmp_path / "points.json"), "-o", str(tmp_path / "mp")]) == 0
    assert "rigged" in capsys.readouterr().out
    assert (tmp_path / "mp").is_dir()


def test_a_flattened_face_is_refused_in_one_line_naming_the_empty_regions(default, tmp_path, capsys):
    """A face pressed to a relief (a character drawn nearly flat) has no skin in front of its jaw
    angles: its regions came out empty and the rig ended in a numpy traceback; now one line."""
    skin = default.parts["skin"]
    remap = np.full(len(default.vertices), -1)
    remap[skin] = np.arange(len(skin))
    triangles = remap[default.triangles]
    flat = default.vertices[skin] * (1.0, 1.0, 0.05)
    mesh = write_bare_obj(tmp_path / "flat.obj", flat, triangles[(triangles >= 0).all(axis=1)])
    marks = {f: int(remap[v]) for f, v in default.feature_vertices.items() if remap[v] >= 0}
    (tmp_path / "points.json").write_text(json.dumps(marks))
    assert main(["rig", str(mesh), "--landmarks", str(tmp_path / "points.json"), "-o", str(tmp_path / "f")]) != 0
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("puppet rig: face 'flat': no skin for the forehead") and "flat face" in line, line


def test_a_landmark_file_that_is_not_json_is_named(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{2.1: 3")
    with pytest.raises(LandmarkError, match="bad.json:1: not valid JSON"):
        read_landmarks(bad, 10)


def _ibug_for(face) -> list[int]:
    """68 iBUG vertices of the default face: the FDPs where iBUG has them, points one and two
    thirds along the lid and lower-lip loops for the rest of the eyes and lips."""
    fv = face.feature_vertices
    ibug = [fv["2.1"]] * 68
    for fid, i in IBUG_FDP.items():
        ibug[i] = fv[fid]
    for contour, start, end, via, slots in (
        ("left_lid_opening", "3.11", "3.7", "3.1", (43, 44)), ("left_lid_opening", "3.7", "3.11", "3.3", (46, 47)),
        ("right_lid_opening", "3.12", "3.8", "3.2", (37, 38)), ("right_lid_opening", "3.8", "3.12", "3.4", (40, 41)),
        ("vermilion_border", "8.3", "8.2", "8.7", (55, 56)), ("vermilion_border", "8.2", "8.4", "8.8", (58, 59)),
    ):
        loop = [int(v) for v in face.contours[contour]]
        path = _loop_path_via(loop, loop.index(fv[start]), loop.index(fv[end]), fv[via])
        for slot, f in zip(slots, (1 / 3, 2 / 3)):
            ibug[slot] = path[round(f * (len(path) - 1))]
    return ibug


def test_68_ibug_points_rig_the_default_face(default, tmp_path):
    mesh = write_bare_obj(tmp_path / "m.obj", default.vertices, default.triangles)
    face = load_face(mesh, landmarks=_ibug_for(default))
    rig = build_rig(face)
    assert _covered_once(face, rig)
    size = np.linalg.norm(default.feature_points["3.5"] - default.feature_points["3.6"])
    for fid in ("3.1", "3.3", "8.7", "5.1", "2.13", "11.1", "9.7"):
        assert np.linalg.norm(face.feature_points[fid] - default.feature_points[fid]) < 0.35 * size, fid
    moved = Runtime(face, rig, cache=False).deform_faps(expression=(1, 63, 0, 0)) - face.vertices
    assert np.isfinite(moved).all() and np.abs(moved).max() > 0.01 * size


@pytest.fixture(scope="module")
def bare_default(default, tmp_path_factory):
    """The default face written as a bare OBJ (positions and triangles) and loaded from its own
    feature-point vertices: a user's mesh the shipped face's artist made."""
    mesh = write_bare_obj(tmp_path_factory.mktemp("bare") / "f.obj", default.vertices, default.triangles)
    return load_face(mesh, landmarks=dict(default.feature_vertices))


def test_a_bare_default_face_gets_the_default_faces_parts(default, bare_default):
    """Gums are flat arches (teeth, not a mouth socket), the tongue is deeper than wide, and every
    tooth goes with its gum: the parts are the artist's, so no mouth piece lands in the lips."""
    assert {k: sorted(v) for k, v in bare_default.parts.items()} == {k: sorted(v) for k, v in default.parts.items()}


def test_a_bare_default_face_gets_the_default_faces_jaw_band(default, bare_default):
    """The face oval runs through the chin, jaw and hairline points, so the skin under the jaw line
    goes with the jaw as on the default face: the cheeks are the artist's rig's cheeks."""
    assert set(bare_default.contours) >= {"face_oval", "mouth_opening", "vermilion_border"}
    sizes = {r.name: len(r.vertices) for r in build_rig(bare_default).regions}
    shipped = {r.name: len(r.vertices) for r in build_rig(default).regions}
    assert sizes.keys() == shipped.keys()
    assert all(abs(sizes[k] - shipped[k]) <= 0.02 * shipped[k] for k in shipped), (sizes, shipped)


def test_a_bare_default_face_finds_its_neck_cut(default, bare_default):
    """The skin's open boundary below the chin is the neck cut, so the head turns over the same
    neck band as on the default face; a mask's rim, up past the chin, is none."""
    assert sorted(bare_default.contours["neck_cut"]) == sorted(default.contours["neck_cut"])
    neck = build_rig(bare_default).rigid_parts["head"].neck
    assert np.allclose(neck, build_rig(default).rigid_parts["head"].neck, atol=1e-6)


def test_a_bare_default_face_rigs_with_few_folds_and_creases(default, bare_default):
    """The 6 expressions and 15 visemes at full strength, without fold limits: the folds and creases
    it reaches now (21 and 239), near the default face's own ``build_rig`` without limits (19 folds,
    15 of them joy's hidden corner slivers, and 180 creased edges; the shipped rig's limits and
    guard take them to none), and with fold limits as ``puppet rig`` finds them: no fold (what
    the limits left is the rig's ``guarded``, which the fold guard holds) and 59 creases (54
    before joy's corners went past the editor's end; main had 51 and 709 once), asserted so they
    cannot grow back. Its mesh is as coarse as the default face's, so nothing is smoothed
    (``puppet.runtime.creasesmoothing``)."""
    from puppet.face.default import load_default_rig
    from puppet.runtime.foldlimits import fold_limited
    from puppet.runtime.posecheck import pose_flaws
    reference = Runtime(default, load_default_rig())
    rig = build_rig(bare_default)
    found = pose_flaws(Runtime(bare_default, rig), reference)
    assert sum(f.folds for f in found.values()) <= 21
    assert sum(f.creases for f in found.values()) <= 240
    limited_rig = fold_limited(bare_default, rig)  # as `puppet rig`
    assert len(limited_rig.guarded) > 0
    assert len(limited_rig.smoothed) == 0  # as coarse as the reference: its creases are the motion's
    limited = pose_flaws(Runtime(bare_default, limited_rig), reference)
    assert sum(f.folds for f in limited.values()) == 0
    assert sum(f.creases for f in limited.values()) <= 60


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(0, 300), st.integers(0, 4), st.floats(0.01, 0.6))
def test_the_skin_grid_picks_what_the_plain_greedy_pick_does(seed, n, n_taken, spacing):
    """``_spread_out`` (a k-d tree finds the candidates near each pick) picks exactly the vertices
    that checking every later candidate's distance picks: in order, each at least ``spacing`` from
    the ones before and from ``taken``."""
    rng = np.random.default_rng(seed)
    v = rng.uniform(-1, 1, size=(n + 5, 3))
    candidates = rng.permutation(n + 5)[:n]
    taken = list(rng.uniform(-1, 1, size=(n_taken, 3)))
    plain: list[int] = []
    for c in candidates:
        others = [v[k] for k in plain] + taken
        if all(np.linalg.norm(v[c] - o) >= spacing for o in others):
            plain.append(int(c))
    assert _spread_out(v, candidates, taken, spacing) == plain


def test_a_contour_leg_sought_near_its_ends_is_the_whole_skin_s_shortest_path(default):
    """``landmarks._leg`` looks within a few straight distances of its ends first: the path it
    finds is the one a search of the whole skin finds, with and without vertices blocked."""
    from scipy.sparse.csgraph import dijkstra

    from puppet.face.landmarks import _leg, _skin_graph

    v, tri = np.asarray(default.vertices, float), np.asarray(default.triangles)
    skin = _skin_graph(v, tri, np.ones(len(v), dtype=bool), np.zeros((0, 2), dtype=np.int64))
    rng = np.random.default_rng(5)
    for _ in range(12):
        a, b = (int(k) for k in rng.choice(len(v), 2, replace=False))
        blocked = rng.random(len(v)) < 0.05
        blocked[[a, b]] = False
        keep = (~blocked).astype(float)
        graph = skin.graph.multiply(keep[:, None]).multiply(keep[None, :]).tocsr()
        graph.eliminate_zeros()  # an explicit zero is an edge of no length to dijkstra
        _, pred = dijkstra(graph, directed=False, indices=a, return_predecessors=True)
        whole, k = [], b
        while 0 <= k != a:
            whole.append(int(k))
            k = pred[k]
        assert _leg(skin, a, b, blocked) == (whole[::-1] if k == a else [])
