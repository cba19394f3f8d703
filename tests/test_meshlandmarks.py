"""Landmarks found on a mesh by themselves (puppet.view.meshlandmarks): on the default face written
out as a bare OBJ, however it is turned in its file; a mesh with no face refused in one line;
``puppet rig`` without --landmarks making a face folder that loads and poses; and the picker on
a mesh (puppet.view.meshpicker), which needs no detector."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from puppet import cli
from puppet.face.autorig import rig_for_face
from puppet.face.default import default_face
from puppet.face.landmarks import FDP_NEEDED, read_landmarks
from puppet.face.load import load_face
from puppet.face.meshfile import load_mesh, write_bare_obj
from puppet.photo.build import MEDIAPIPE_FDP
from puppet.photo.carriedpoints import FACE_SIDES, OWN_PLACE, carried_points, found_fdps, mediapipe_reference
from puppet.photo.detect import PHOTO_PYTHON, photo_python
from puppet.runtime.runtime import Runtime

needs_detector = pytest.mark.skipif(photo_python() is None,
                                    reason="no photo environment (.venv-photo: tools/setup.sh makes it)")
TURNS = {"upside down": Rotation.from_euler("z", 180, degrees=True),
         "looking along +x": Rotation.from_euler("y", 90, degrees=True),
         "tilted 30 and rolled 20 degrees": Rotation.from_euler("xz", [30, 20], degrees=True)}


@pytest.fixture(scope="module")
def default_obj(tmp_path_factory) -> Path:
    face = default_face()
    return write_bare_obj(tmp_path_factory.mktemp("mesh") / "head.obj", face.vertices, face.triangles)


@pytest.fixture(scope="module")
def found(default_obj):
    from puppet.view.meshlandmarks import find_landmarks

    return find_landmarks(load_mesh(default_obj), str(default_obj))


def errors(found, truth: dict[str, int]) -> dict[str, float]:
    """Per FDP both have, the distance between the found and the true vertex, in face widths."""
    return found.errors(default_face().vertices, truth)


@needs_detector
def test_the_default_faces_landmarks_are_found_near_its_own(found):
    own = {f: int(v) for f, v in default_face().feature_vertices.items()}
    error = errors(found, own)
    assert set(FDP_NEEDED) <= set(found.fdp) and len(error) >= 40
    assert np.median(list(error.values())) < 0.03  # 1.8% measured (tools/checks/landmark_accuracy.py)
    assert np.percentile(list(error.values()), 90) < 0.10
    assert max(error[f] for f in ("3.7", "3.8", "3.11", "3.12", "8.3", "8.4", "9.3")) < 0.03  # corners, nose tip
    assert found.views_found == 5 and "5 of 5 views" in found.summary()


JAW_AND_HAIRLINE = ("2.11", "2.12", "2.13", "2.14", "11.1", "11.2", "11.3")  # the face oval's points


@needs_detector
def test_the_points_mediapipe_has_none_for_are_carried_onto_the_default_faces_own(found):
    """The jaw line, cheeks, ears and hairline come with the points found (carried from the
    default face), not left to ``apply_landmarks``, and so do the chin and the lid creases, which
    the default face puts elsewhere than MediaPipe: on the default face they are its own (its
    chin, taken from MediaPipe's 152, lay 15.9% of the face width off, on the chin's front)."""
    own = {f: int(v) for f, v in default_face().feature_vertices.items()}
    error = errors(found, {f: v for f, v in own.items() if f not in found.spread})
    assert len(error) == 31 and len(found.fdp) == len(found.spread) + 31 and "31 more carried" in found.summary()
    assert max(error[f] for f in (*JAW_AND_HAIRLINE, *OWN_PLACE)) < 0.02 and np.median(list(error.values())) < 0.01


def test_the_chin_and_lid_creases_are_carried_to_the_default_faces_own_places():
    """The warp of MediaPipe's landmarks where they lie on the default face carries its chin (under
    the chin; MediaPipe's 152 is on its front, 13% of the face width away) and its upper lids'
    creases onto its own vertices, as it carries the jaw line (no detector needed)."""
    face = default_face()
    vertices = np.asarray(face.vertices, float)
    landmarks = cKDTree(vertices).query(mediapipe_reference())[1]
    taken = [int(landmarks[i]) for i in found_fdps()]
    carried = carried_points(vertices, np.asarray(face.parts["skin"]), landmarks, taken)
    assert OWN_PLACE <= set(carried) and not OWN_PLACE & set(found_fdps().values())
    width = np.linalg.norm(np.subtract(*mediapipe_reference()[list(FACE_SIDES)]))
    for fdp in OWN_PLACE:
        assert np.linalg.norm(vertices[carried[fdp]] - vertices[face.feature_vertices[fdp]]) < 0.01 * width, fdp


def test_a_feature_point_no_view_sees_head_on_is_taken_from_all_the_views_that_see_it():
    """A lip corner in its crease is seen within ``MIN_FACING`` of head-on by no view: taken from
    the most frontal alone, on a shape-model face that was a view turned 25 degrees which saw the
    upper lip in front of the corner, and the inner corner 2.5 fell on 2.2's vertex (the rig
    refused the face). All the views that see a feature point vote now; another landmark seen
    so (the face oval's, edge-on) is still taken from the most frontal one."""
    from puppet.view.meshlandmarks import MIN_FACING, _views_used

    seen = np.ones(5, dtype=bool)
    facing = np.array([0.14, 0.48, 0.09, 0.32, 0.03])  # 2.5 on that face: view 1 the turned one
    assert facing.max() < MIN_FACING and _views_used(seen, seen, facing, True).all()
    assert _views_used(seen, seen, facing, False).tolist() == [False, True, False, False, False]
    facing[2] = 0.9
    assert _views_used(seen, seen, facing, True).tolist() == [False, False, True, False, False]


def test_two_feature_points_found_on_one_vertex_are_set_apart():
    """Two feature points snapped to one vertex stop the rig (a control point on each): the one
    whose lifts lie nearer keeps it, the other takes the nearest vertex no other point holds (on a
    shape-model face, the lower inner lip's middle and side, 2.3 and 2.8)."""
    from puppet.view.meshlandmarks import N_MESH, _distinct

    vertices = np.c_[np.arange(10.0), np.zeros(10), np.zeros(10)]
    rows = {None: (np.arange(10), cKDTree(vertices))}
    middle, side = 14, 402  # MediaPipe's 2.3 and 2.8
    chosen = np.full(N_MESH, -1)
    chosen[[middle, side]] = 5
    lifts = np.full((2, N_MESH, 3), np.nan)
    lifts[:, middle] = [[5.0, 0.1, 0.0], [5.1, 0.0, 0.0]]
    lifts[:, side] = [[4.4, 0.0, 0.0], [4.2, 0.0, 0.0]]
    _distinct(chosen, vertices, rows, lifts, np.ones(2, dtype=bool))
    assert (chosen[middle], chosen[side]) == (5, 4)


def test_lids_found_in_a_slit_under_the_eye_move_onto_the_eye_openings_edge(egl):
    """On a bare mesh the eyes render skin-coloured, and on a shape-model face MediaPipe saw a slit
    under the eye: the upper lids' middles (3.1, 3.2) came 8-9% of the face width low, on the lower
    lid, the lower ones below it. Moved onto the edge of the opening the front view of the skin
    alone sees (no detector needed: the default face's MediaPipe landmarks, its lid middles put
    under its eyes as there), each lands on the default face's own point; found right, it stays,
    and so do the corners, taken where the opening ends."""
    from puppet.runtime.normals import VertexNormals
    from puppet.view.meshlandmarks import EYES, FACE_SHARE, Shots, _lid_edges

    face = default_face()
    vertices, skin = np.asarray(face.vertices, float), np.asarray(face.parts["skin"])
    width = np.linalg.norm(np.subtract(*mediapipe_reference()[list(FACE_SIDES)]))
    tree = cKDTree(vertices[skin])
    right = skin[tree.query(mediapipe_reference())[1]]
    own = {i: face.feature_vertices[MEDIAPIPE_FDP[i]] for eye in EYES for i in eye}
    assert all(right[i] == v for i, v in own.items())
    slit = right.copy()
    for upper, lower, *_ in EYES:
        under = vertices[own[lower]] - [0.0, 0.05 * width, 0.0]
        slit[[upper, lower]] = skin[tree.query([under + [0.0, 0.02 * width, 0.0], under])[1]]
    normals = VertexNormals(np.asarray(face.triangles), len(vertices))(vertices)
    with Shots(face, 640) as shots:
        camera = shots.framing(np.eye(3), vertices[right], FACE_SHARE)
        surface = shots.skin_surface(camera, skin)
    for start in (slit, right):
        chosen = start.copy()
        _lid_edges(chosen, vertices, normals, skin, camera, surface)
        assert {i: chosen[i] for i in own} == own


@needs_detector
@pytest.mark.slow
def test_the_lids_of_a_face_of_another_shape_are_found_on_its_eye_openings_edge(tmp_path):
    """Seed 2 of the shape model (as below): MediaPipe saw a slit under its skin-coloured eyes,
    and the lid middles found lay 3.5-9.5% of the face width from the given ones (the upper lids
    on the lower lid), the corners 3-5%, and the transfer's residual was 0.41 (0.36 from the given
    landmarks). Taken from the eye opening's edge, each lid middle lies within 1.5% and each
    corner within 3.5% (1.3-2.8%; the residual 0.39)."""
    from puppet.photo.shapemodel import load_shape_model
    from puppet.view.meshlandmarks import find_landmarks

    face, model = default_face(), load_shape_model()
    weights = np.random.default_rng(2).normal(size=len(model)) * 2.0
    vertices = np.asarray(face.vertices, float) + model.offsets(weights)
    mesh = write_bare_obj(tmp_path / "shaped.obj", vertices, face.triangles)
    found = find_landmarks(load_mesh(mesh), str(mesh))
    error = found.errors(vertices, {f: int(face.feature_vertices[f]) for f in face.feature_vertices})
    assert max(error[f] for f in ("3.1", "3.2", "3.3", "3.4")) < 0.015, error
    assert max(error[f] for f in ("3.7", "3.8", "3.11", "3.12")) < 0.035, error


@needs_detector
@pytest.mark.parametrize("turn", TURNS)
def test_a_face_turned_in_its_file_is_found_the_same(found, turn, tmp_path):
    from puppet.view.meshlandmarks import find_landmarks

    face = default_face()
    turned = write_bare_obj(tmp_path / "turned.obj", TURNS[turn].apply(face.vertices) + [3.0, -2.0, 1.0],
                            face.triangles)
    again = find_landmarks(load_mesh(turned), str(turned))
    assert np.median(list(errors(again, found.fdp).values())) < 0.01
    assert np.degrees(Rotation.from_matrix(again.rotation @ TURNS[turn].as_matrix()).magnitude()) < 10


def refusals(err: str) -> list[str]:
    """A command's refusal lines (its progress lines, "rig 1/5: ...", come before them)."""
    return [line for line in err.splitlines() if line.startswith("puppet ")]


@needs_detector
def test_a_mesh_with_no_face_is_refused_in_one_line(tmp_path, capsys):
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    mesh = write_bare_obj(tmp_path / "ball.obj", sphere.vertices, sphere.faces)
    assert cli.main(["rig", str(mesh), "-o", str(tmp_path / "ball")]) == 2
    lines = refusals(capsys.readouterr().err)
    assert len(lines) == 1 and lines[0].startswith(f"puppet rig: no face found in 25 rendered views of {mesh}: its 24")
    assert not (tmp_path / "ball").exists()


def test_without_the_photo_environment_rig_says_how_to_get_it_in_one_line(default_obj, tmp_path, capsys,
                                                                          monkeypatch):
    monkeypatch.setenv(PHOTO_PYTHON, str(tmp_path / "no-python"))
    assert cli.main(["rig", str(default_obj), "-o", str(tmp_path / "me")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"puppet rig: {default_obj}: finding landmarks needs the photo")
    assert not (tmp_path / "me").exists()


@needs_detector
def test_rig_without_landmarks_makes_a_face_folder_that_loads_and_poses(default_obj, tmp_path, capsys):
    folder = tmp_path / "me"
    assert cli.main(["rig", str(default_obj), "-o", str(folder)]) == 0
    out, err = capsys.readouterr()
    assert [line.split(":")[0] for line in err.splitlines() if line.startswith("rig ")
            and line[4].isdigit()] == [f"rig {k}/5" for k in range(1, 6)]
    assert "landmarks: found 39 feature points in 5 of 5 views" in out and "pick-landmarks" in out
    marks = read_landmarks(folder / "landmarks.json", len(default_face().vertices))
    face = load_face(folder)
    assert isinstance(marks, dict) and all(face.feature_vertices[f] == v for f, v in marks.items())
    runtime = Runtime(face, rig_for_face(face))
    rest, joy = runtime.deform_faps(), runtime.deform_faps(expression=(1, 63, 0, 0))
    corners = [face.feature_vertices[f] for f in ("8.3", "8.4")]
    mouth = np.linalg.norm(face.vertices[corners[0]] - face.vertices[corners[1]])
    assert np.allclose(rest, face.vertices) and (joy - rest)[corners, 1].min() > 0.02 * mouth  # the corners rise


def test_the_picker_on_a_mesh_moves_a_dragged_point_onto_the_vertex_under_it(default_obj, tmp_path):
    from puppet.view.meshlandmarks import project
    from puppet.view.meshpicker import MeshPickerServer

    face = default_face()
    start = {f: int(face.feature_vertices[f]) for f in FDP_NEEDED}
    picker = MeshPickerServer(default_obj, tmp_path / "marks.json", start=start)
    try:
        page = urllib.request.urlopen(picker.url, timeout=5).read().decode()
        assert '"9.3"' in page and "LABELS" not in page
        served = json.loads(urllib.request.urlopen(picker.url + "start", timeout=5).read())
        points = np.array(served["points"])
        assert served["layout"] == "mesh" and points.shape == (len(start), 2)
        off = points.copy()
        off[0] = [1.0, 1.0]  # the background, off the mesh
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(_post(picker.url, off), timeout=5)
        assert refused.value.code == 400 and "off the mesh" in refused.value.read().decode()
        assert not picker.saved.is_set()
        target = int(face.feature_vertices["9.1"])  # the nose's side: drag the tip onto it
        moved = points.copy()
        moved[picker.labels.index("9.3")] = project(picker.camera, face.vertices[[target]], picker.size)[0]
        urllib.request.urlopen(_post(picker.url, moved), timeout=5)
    except BaseException:
        picker.close()
        raise
    saved = json.loads(picker.wait(timeout=5).read_text())
    assert {f: v for f, v in saved.items() if f != "9.3"} == {f: v for f, v in start.items() if f != "9.3"}
    width = np.ptp(face.vertices[:, 0])
    assert np.linalg.norm(face.vertices[saved["9.3"]] - face.vertices[target]) < 0.01 * width
    assert read_landmarks(tmp_path / "marks.json", len(face.vertices)) == saved  # rig --landmarks reads it


def _post(url: str, points: np.ndarray) -> urllib.request.Request:
    return urllib.request.Request(url + "points", data=json.dumps({"points": points.tolist()}).encode(),
                                  headers={"Content-Type": "application/json"})


@needs_detector
@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_a_face_of_another_shape_rigs_from_its_found_landmarks(tmp_path, capsys, seed):
    """Faces of other shapes (the shipped shape model, two standard deviations out), as bare OBJs:
    ``puppet rig`` without --landmarks rigs them. Their closed mouths' inner lip points were lifted
    onto the other lip or into the mouth, the lip loop ran over the lips (75 vertices for 38) and
    rig stopped on control points in one place; each now lies on its own lip, above its pair."""
    from puppet.photo.shapemodel import load_shape_model

    face, model = default_face(), load_shape_model()
    weights = np.random.default_rng(seed).normal(size=len(model)) * 2.0
    mesh = write_bare_obj(tmp_path / "shaped.obj", np.asarray(face.vertices, float) + model.offsets(weights),
                          face.triangles)
    assert cli.main(["rig", str(mesh), "-o", str(tmp_path / "me")]) == 0, capsys.readouterr().err
    rigged = load_face(tmp_path / "me")
    loop, border = rigged.contours["mouth_opening"], rigged.contours["vermilion_border"]
    assert len(loop) <= 1.2 * len(face.contours["mouth_opening"]) and not set(loop) & set(border)
    fv, up = rigged.feature_vertices, rigged.vertices[:, 1]
    assert all(up[fv[a]] > up[fv[b]] for a, b in (("2.2", "2.3"), ("2.6", "2.8"), ("2.7", "2.9")))
    shaped, eyes = np.asarray(face.vertices, float) + model.offsets(weights), 1024 * face.fapu["ES0"]
    for mid in ("2.2", "2.3"):  # on the lips' edges: lifted onto a tooth between them, 2.2 took the wall behind
        assert abs(shaped[fv[mid], 2] - shaped[face.feature_vertices[mid], 2]) < 0.03 * eyes


@needs_detector
@pytest.mark.slow
def test_a_face_whose_upper_lip_stands_over_the_lower_rigs_from_its_found_landmarks(tmp_path, capsys):
    """Seed 3 of the shape model (as above): its upper lip stands over the lower. The inner lip
    corner 2.5, seen head-on by no view, was taken from a turned view that saw the upper lip in
    front of it and fell on 2.2's vertex; taken from all the views, 2.3 and 2.8 then fell on one
    vertex. ``puppet rig`` refused the face both times; each point now has a vertex of its own."""
    from puppet.photo.shapemodel import load_shape_model

    face, model = default_face(), load_shape_model()
    weights = np.random.default_rng(3).normal(size=len(model)) * 2.0
    vertices = np.asarray(face.vertices, float) + model.offsets(weights)
    mesh = write_bare_obj(tmp_path / "shaped.obj", vertices, face.triangles)
    assert cli.main(["rig", str(mesh), "-o", str(tmp_path / "me")]) == 0, capsys.readouterr().err
    found = read_landmarks(tmp_path / "me" / "landmarks.json", len(vertices))
    assert len(set(found.values())) == len(found)
    width = np.linalg.norm(np.subtract(*vertices[[face.feature_vertices["3.7"], face.feature_vertices["3.12"]]]))
    assert np.linalg.norm(vertices[found["2.5"]] - vertices[face.feature_vertices["2.5"]]) < 0.15 * width


@needs_detector
@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_a_face_of_another_shape_gets_its_chin_jaw_angles_and_hairline_near_the_given_ones(tmp_path, seed):
    """On faces of other shapes (as above, whose feature points are the default face's vertices),
    the face oval's points found lie within 15% of the face width of the given ones: placed by
    ``apply_landmarks`` from the points MediaPipe gives, they lay 20-85% off (the jaw angle 2.13
    76% on seed 1; the hairline 80%) and the transfer's residual rose from 0.35 to 0.40 and 0.52
    (``tools/checks/transfer_check.py --found``); carried, 0.38 and 0.42. The chin 2.1 too, under the
    chin as the default face's: taken from MediaPipe's 152 (the chin's front) it lay 22-26% off,
    and the residual on seed 2 was 0.44 (0.39 carried; from the given landmarks 0.36)."""
    from puppet.photo.shapemodel import load_shape_model
    from puppet.view.meshlandmarks import found_face

    face, model = default_face(), load_shape_model()
    weights = np.random.default_rng(seed).normal(size=len(model)) * 2.0
    vertices = np.asarray(face.vertices, float) + model.offsets(weights)
    mesh = write_bare_obj(tmp_path / "shaped.obj", vertices, face.triangles)
    rigged, found = found_face(load_mesh(mesh), str(mesh))
    error = {f: np.linalg.norm(vertices[rigged.feature_vertices[f]] - vertices[face.feature_vertices[f]])
             / found.face_width for f in (*JAW_AND_HAIRLINE, "2.1")}
    assert max(error.values()) < 0.15, error
