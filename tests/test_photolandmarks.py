"""Landmarks found in a photo offline (MediaPipe in the photo environment), and what is refused:
no face, several faces, no photo environment."""

from __future__ import annotations

import numpy as np
import pytest
from photoseam import seam
from PIL import Image

from puppet.face.load import load_face
from puppet.photo.detect import PHOTO_PYTHON, DetectionError, detect_landmarks, photo_python

needs_detector = pytest.mark.skipif(photo_python() is None,
                                    reason="no photo environment (.venv-photo: tools/setup.sh makes it)")


@pytest.fixture(scope="module")
def astronaut(tmp_path_factory):
    data = pytest.importorskip("skimage.data", reason="scikit-image (the test extra) has the astronaut photo")
    path = tmp_path_factory.mktemp("photos") / "astronaut.png"
    Image.fromarray(data.astronaut()).save(path)
    return path


@needs_detector
def test_the_astronauts_landmarks_are_found_on_her_face(astronaut):
    found = detect_landmarks(astronaut)
    points = np.array(found["points"])
    assert found["layout"] == "mediapipe468" and points.shape == (478, 3)
    left_eye, right_eye, nose = points[33], points[263], points[1]  # outer eye corners, nose tip
    assert 150 < nose[0] < 260 and 120 < nose[1] < 230  # the face sits at about (210, 170) in 512 x 512
    assert left_eye[0] < nose[0] < right_eye[0] and nose[1] > max(left_eye[1], right_eye[1])


def refusals(err: str) -> list[str]:
    """The refusal lines of a command's stderr (its progress lines, "face-from-photo 1/4: ...",
    come before them)."""
    return [line for line in err.splitlines() if line.startswith("puppet ")]


@needs_detector
def test_face_from_photo_with_no_landmarks_detects_them_and_builds_a_face(astronaut, tmp_path):
    from puppet import cli

    assert cli.main(["face-from-photo", str(astronaut), "-o", str(tmp_path / "me")]) == 0
    face = load_face(tmp_path / "me")
    assert len(face.vertices) == len(load_face().vertices) and face.name == "astronaut"


@needs_detector
def test_a_photo_with_no_face_or_two_is_refused_in_one_line(astronaut, tmp_path, capsys):
    from puppet import cli

    photo = np.asarray(Image.open(astronaut))
    blank, two = tmp_path / "wall.png", tmp_path / "two.png"
    Image.fromarray(np.full((512, 512, 3), 128, np.uint8)).save(blank)
    face = photo[20:300, 100:380]
    Image.fromarray(np.concatenate([face, face], axis=1)).save(two)
    assert cli.main(["face-from-photo", str(blank), "-o", str(tmp_path / "a")]) == 2
    assert cli.main(["face-from-photo", str(two), "-o", str(tmp_path / "b")]) == 2
    err = refusals(capsys.readouterr().err)
    assert err == [f"puppet face-from-photo: {blank}: no face found: expected a frontal photo with the whole "
                   "face in view",
                   f"puppet face-from-photo: {two}: 2 faces found: crop the photo to the one face to build"]
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_with_no_photo_environment_it_says_how_to_get_one(monkeypatch, tmp_path):
    monkeypatch.setenv(PHOTO_PYTHON, str(tmp_path / "nowhere" / "python"))
    with pytest.raises(DetectionError, match="run tools/setup.sh, or set FACEPUPPET_PHOTO_PYTHON"):
        detect_landmarks(tmp_path / "me.png")


@pytest.fixture(scope="module")
def default_face_views(tmp_path_factory, egl):
    """Renders of the default face: {yaw degrees: png path}, and the front camera's projector."""
    from puppet.view.renderer import Renderer, save_png

    face = load_face()
    folder = tmp_path_factory.mktemp("views")
    paths = {}
    with Renderer.for_face(face, width=512, height=512) as renderer:
        front = renderer.aim(face.vertices[face.parts["skin"]], view="front", margin=1.3)
        projected = renderer.project(np.asarray(face.vertices))
        distance = np.linalg.norm(front.eye - front.target)
        for yaw in (0, 60, 90):
            turn = np.radians(yaw)
            renderer.look_at(front.target + distance * np.array([np.sin(turn), 0.0, np.cos(turn)]), front.target,
                             fov=front.fov)
            paths[yaw] = folder / f"yaw{yaw}.png"
            save_png(renderer.render(face.vertices), paths[yaw])
    return paths, projected


@needs_detector
def test_mediapipe_finds_its_landmarks_on_the_default_face_where_the_map_puts_them(default_face_views):
    from puppet.photo.build import mediapipe_points

    paths, projected = default_face_views
    face = load_face()
    found = np.array(detect_landmarks(paths[0])["points"])[:468, :2]
    points = mediapipe_points(face)
    mapped = np.einsum("mk,mkd->md", points.weights, projected[points.vertices])
    width = np.linalg.norm(found[234] - found[454])
    error = np.linalg.norm(found - mapped, axis=1) / width
    assert np.median(error) < 0.01 and np.percentile(error, 90) < 0.02


@needs_detector
def test_a_turned_or_profile_photo_is_refused_in_one_line(default_face_views, tmp_path, capsys):
    from puppet import cli

    paths, _ = default_face_views
    assert cli.main(["face-from-photo", str(paths[60]), "-o", str(tmp_path / "a")]) == 2
    assert cli.main(["face-from-photo", str(paths[90]), "-o", str(tmp_path / "b")]) == 2
    turned, profile = refusals(capsys.readouterr().err)
    assert "not a frontal face" in turned and "the head is turned" in turned
    assert profile == f"puppet face-from-photo: {paths[90]}: no face found: expected a frontal photo with the whole face in view"
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@needs_detector
def test_the_astronauts_smile_is_taken_out_and_her_skin_goes_round_the_head(astronaut):
    """The astronaut smiles with parted lips (teeth showing): the face built from her photo has
    the lips closed as the default face's, and where her photo fades out (into hair and the
    collar of her suit, painted out) its colour meets the vertex colour without a seam."""
    from puppet.photo import build as pf

    face = load_face()
    landmarks = pf.parse_landmarks(detect_landmarks(astronaut))
    photo = pf.read_photo(astronaut)
    built, report = pf.face_from_photo(photo, landmarks, "astronaut")
    assert report["expression_faps"]["open_jaw"] > 30 and report["expression_faps"]["raise_b_midlip"] < -100
    width = np.ptp(face.vertices[face.contours["face_oval"], 0])
    points = dict(zip(range(468), landmarks.points))
    eyes = np.linalg.norm(points[33] - points[263])
    assert np.linalg.norm(points[13] - points[14]) > 0.08 * eyes  # in the photo the lips are parted (at rest 0.01)
    fv = face.feature_vertices
    gap, rest = (v[fv["2.2"], 1] - v[fv["2.3"], 1] for v in (built.vertices, face.vertices))
    assert abs(gap - rest) < 0.003 * width
    assert seam(built) < 0.08
