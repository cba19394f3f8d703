"""Landmarks found in a photo offline (MediaPipe in the photo environment), and what is refused:
no face, several faces, no photo environment."""

from __future__ import annotations

import numpy as np
import pytest
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
    err = capsys.readouterr().err.splitlines()
    assert err == [f"puppet face-from-photo: {blank}: no face found: expected a frontal photo with the whole "
                   "face in view",
                   f"puppet face-from-photo: {two}: 2 faces found: crop the photo to the one face to build"]
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_with_no_photo_environment_it_says_how_to_get_one(monkeypatch, tmp_path):
    monkeypatch.setenv(PHOTO_PYTHON, str(tmp_path / "nowhere" / "python"))
    with pytest.raises(DetectionError, match="run tools/setup.sh, or set FACEPUPPET_PHOTO_PYTHON"):
        detect_landmarks(tmp_path / "me.png")
