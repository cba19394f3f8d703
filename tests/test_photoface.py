"""A face from one frontal photo (puppet.photo.build), its folder (puppet.face.folder), the picker
(puppet.view.picker) and the command. The photo is the default face itself, rendered frontally with a
long lens (nearly the orthographic projection the fit assumes), so the rebuilt face must be the
default face again."""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import numpy as np
import pytest
from photoseam import seam

from puppet.cli import main
from puppet.face.folder import load_face_folder, load_folder_rig
from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.photo import build as pf
from puppet.runtime.runtime import Runtime
from puppet.view.picker import PickerServer

SIZE = 512


@pytest.fixture(scope="module")
def shot(egl):
    """(photo, projector): the default face rendered frontally, and its camera's projection."""
    from puppet.view.renderer import Renderer

    face = load_face()
    with Renderer(face.triangles, len(face.vertices), face.colors, width=SIZE, height=SIZE) as renderer:
        renderer.aim(face.vertices, view="front", fov=8.0)
        yield renderer.render(face.vertices), renderer.project


@pytest.fixture(scope="module")
def fdp11(shot):
    _, project = shot
    face = load_face()
    return pf.parse_landmarks({"layout": "fdp11", "points": project(np.array([face.feature_points[k] for k in pf.FDP11])).tolist()})


def _aligned_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-vertex distance of a to b after the least-squares similarity of a onto b."""
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    u, sig, vt = np.linalg.svd((b - mb).T @ (a - ma))
    d = np.ones(3)
    d[-1] = np.sign(np.linalg.det(u @ vt))
    rotation = u @ np.diag(d) @ vt
    scale = (sig * d).sum() / ((a - ma) ** 2).sum()
    return np.linalg.norm(scale * (a - ma) @ rotation.T + mb - b, axis=1)


def _face_width(face: Face) -> float:
    return float(np.ptp(face.vertices[face.contours["face_oval"], 0]))


@pytest.mark.parametrize("layout", ["fdp11", "ibug68", "mediapipe478"])
def test_the_face_rebuilt_from_its_own_photo_is_the_default_face(shot, layout):
    photo, project = shot
    face = load_face()
    if layout == "fdp11":
        data = {"layout": "fdp11", "points": project(np.array([face.feature_points[k] for k in pf.FDP11])).tolist()}
    elif layout == "ibug68":
        data = project(pf.ibug_points(face).on(face.vertices)).tolist()
    else:  # the 10 iris points of the 478-point form are not used: they sit anywhere inside
        data = np.vstack([project(pf.mediapipe_points(face).on(face.vertices)), np.full((10, 2), SIZE / 2.0)]).tolist()
    rebuilt, report = pf.face_from_photo(photo, pf.parse_landmarks(data))
    error = _aligned_error(rebuilt.vertices, face.vertices) / _face_width(face)
    assert error.mean() < 0.01 and np.percentile(error, 99) < 0.03, (layout, error.mean())
    assert report["similarity_residual"] < 0.05
    assert np.array_equal(rebuilt.triangles, face.triangles)
    assert all(np.array_equal(rebuilt.parts[k], face.parts[k]) for k in face.parts)


def test_texture_coordinates_land_inside_the_image(shot, fdp11):
    photo, _ = shot
    face, report = pf.face_from_photo(photo, fdp11)
    assert face.uv.shape == (len(face.vertices), 2)
    assert ((face.uv >= 0) & (face.uv <= 1)).all()
    textured = face.texture_weight > 0
    assert textured.sum() > 1000 and set(np.flatnonzero(textured)) <= set(face.parts["skin"]) | \
        set(face.parts["eye_l"]) | set(face.parts["eye_r"])
    assert face.texture_weight[face.parts["teeth_upper"]].max() == 0  # teeth keep their colour
    # the photo's cheeks are the default face's skin, so the skin colour is a skin tone
    r, g, b = report["skin_tone"]
    assert r > g > b


def test_the_command_writes_a_folder_that_loads_rigs_and_animates(shot, fdp11, tmp_path, capsys):
    from puppet.view.renderer import render_face, save_png

    photo, _ = shot
    save_png(photo, tmp_path / "photo.png")
    (tmp_path / "points.json").write_text(json.dumps({"layout": "fdp11", "points": fdp11.points.tolist()}))
    assert main(["face-from-photo", str(tmp_path / "photo.png"), "--landmarks", str(tmp_path / "points.json"),
                 "-o", str(tmp_path / "me")]) == 0
    steps = [line.split(":")[0] for line in capsys.readouterr().err.splitlines()]
    assert steps == [f"face-from-photo {k}/4" for k in range(1, 5)]  # its half minute is not silent
    for name in ("face.obj", "texture.png", "face.json", "face.rig"):
        assert (tmp_path / "me" / name).is_file()
    face = load_face_folder(tmp_path / "me")
    assert len(face.vertices) == len(load_face().vertices)
    runtime = Runtime(face, load_folder_rig(tmp_path / "me"))
    chin = face.feature_vertices["2.1"]
    moved = runtime.deform_faps({"open_jaw": 500})
    assert moved[chin, 1] < face.vertices[chin, 1] - 0.01 * _face_width(face)
    plain = Face(face.name, face.vertices, face.triangles, face.parts, colors=face.colors)
    textured, untextured = render_face(face, width=200, height=200), render_face(plain, width=200, height=200)
    assert np.abs(textured.astype(int) - untextured).max() > 30

    from puppet.face.autorig import rig_for_face
    from puppet.face.load import load_face as load_any
    from puppet.io.fapfile import FapWriter

    again = load_any(tmp_path / "me")                     # puppet ... --face me/
    assert rig_for_face(again).face_hash == again.content_hash == load_folder_rig(tmp_path / "me").face_hash
    with FapWriter(tmp_path / "jaw.fap", 25, "jaw") as writer:
        for k in range(4):
            values = np.zeros(68)
            values[2] = 150 * k
            writer.write_frame(values)
    assert main(["render", str(tmp_path / "jaw.fap"), "-o", str(tmp_path / "me.mp4"), "--face",
                 str(tmp_path / "me"), "--size", "64x48"]) == 0
    assert (tmp_path / "me.mp4").stat().st_size > 0


def _points_of(fdp11: pf.Landmarks) -> dict[str, list[float]]:
    return {k: list(p) for k, p in zip(fdp11.keys, fdp11.points)}


def test_missing_required_landmarks_are_named(fdp11):
    points = _points_of(fdp11)
    del points["2.1"]
    with pytest.raises(pf.PhotoFaceError, match=r"missing required landmark.*2\.1.*chin"):
        pf.fit_photo(load_face(), pf.parse_landmarks(points), (SIZE, SIZE))


def test_landmarks_outside_the_image_are_refused(fdp11):
    points = _points_of(fdp11)
    points["9.3"] = [SIZE + 40.0, 10.0]
    with pytest.raises(pf.PhotoFaceError, match=r"outside the 512x512 image: 9\.3"):
        pf.fit_photo(load_face(), pf.parse_landmarks(points), (SIZE, SIZE))


def test_a_turned_head_is_not_frontal(fdp11):
    points = _points_of(fdp11)
    eyes = points["3.7"][0] - points["3.12"][0]
    points["9.3"][0] += 0.3 * eyes  # the nose tip swings toward one side: the head is turned
    with pytest.raises(pf.PhotoFaceError, match="not a frontal face: the nose tip"):
        pf.fit_photo(load_face(), pf.parse_landmarks(points), (SIZE, SIZE))


def test_wrong_counts_and_orders_are_refused(fdp11):
    with pytest.raises(pf.PhotoFaceError, match="12 points"):
        pf.parse_landmarks([[1.0, 2.0]] * 12)
    with pytest.raises(pf.PhotoFaceError, match="needs 68 points, got 11"):
        pf.parse_landmarks({"layout": "ibug68", "points": fdp11.points.tolist()})
    with pytest.raises(pf.PhotoFaceError, match="not MPEG-4 feature point ids"):
        pf.parse_landmarks({"nose": [1, 2]})
    shuffled = pf.Landmarks("fdp", fdp11.points[::-1].copy(), list(fdp11.keys))
    with pytest.raises(pf.PhotoFaceError, match="do not fit a face"):
        pf.fit_photo(load_face(), shuffled, (SIZE, SIZE))


def test_the_picker_saves_what_is_posted(shot, fdp11, tmp_path):
    from puppet.view.renderer import save_png

    save_png(shot[0], tmp_path / "photo.png")
    picker = PickerServer(tmp_path / "photo.png", "fdp11", tmp_path / "points.json")
    try:
        page = urllib.request.urlopen(picker.url, timeout=5).read().decode()
        assert "Save" in page and pf.FDP11_HINTS["3.12"] in page
        assert urllib.request.urlopen(picker.url + "photo", timeout=5).read() == (tmp_path / "photo.png").read_bytes()

        def post(points) -> urllib.request.Request:
            return urllib.request.Request(picker.url + "points", data=json.dumps({"points": points}).encode(),
                                          headers={"Content-Type": "application/json"}, method="POST")

        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(post([[-5.0, 1.0]] * 11), timeout=5)
        assert refused.value.code == 400 and not picker.saved.is_set()
        assert urllib.request.urlopen(post(fdp11.points.tolist()), timeout=5).status == 200
    finally:
        saved = picker.wait(timeout=5)
    assert saved == tmp_path / "points.json"
    landmarks = pf.read_landmarks(saved)
    assert landmarks.layout == "fdp" and np.allclose(landmarks.points, fdp11.points)


# -- a smiling photo, the texture, a turned head ------------------------------------------------

SMILE = {"open_jaw": 250, "raise_l_cornerlip": 180, "raise_r_cornerlip": 180, "raise_l_cornerlip_o": 200,
         "raise_r_cornerlip_o": 200, "stretch_l_cornerlip": 120, "stretch_r_cornerlip": 120,
         "stretch_l_cornerlip_o": 140, "stretch_r_cornerlip_o": 140, "lift_l_cheek": 120, "lift_r_cheek": 120,
         "close_b_l_eyelid": 250, "close_b_r_eyelid": 250}
"""A broad smile with parted lips, written out (not the shipped joy, whose FAPs the FACS fit may
change): what the neutraliser must take out of the mouth, with cheeks and lids it leaves as the
performer's."""


@pytest.fixture(scope="module")
def smiling(egl):
    """(photo, landmarks, posed vertices, projector): the default face smiling with the jaw open
    (``SMILE``: parted lips, teeth showing), rendered frontally; its MediaPipe landmarks projected
    with their exact depth (pixel scale, smaller is nearer)."""
    from puppet.view.renderer import Renderer

    face = load_face()
    posed = Runtime(face).deform_faps(SMILE)
    with Renderer.for_face(face, width=SIZE, height=SIZE) as renderer:
        camera = renderer.aim(face.vertices, view="front", fov=8.0)
        points = pf.mediapipe_points(face).on(posed)
        distance = (points - camera.eye) @ -camera.basis()[2]
        focal = SIZE / 2 / np.tan(np.radians(camera.fov) / 2)
        depth = (distance - distance.mean()) * focal / distance.mean()
        landmarks = pf.parse_landmarks(np.c_[renderer.project(points), depth].tolist())
        yield renderer.render(posed), landmarks, posed, renderer.project


def _mouth(v: np.ndarray, face: Face) -> tuple[float, float]:
    """(lip gap, corners above the lips' middle), / face width."""
    fv = face.feature_vertices
    upper, lower, left, right = (v[fv[k], 1] for k in ("2.2", "2.3", "2.4", "2.5"))
    return (upper - lower) / _face_width(face), ((left + right) - (upper + lower)) / 2 / _face_width(face)


def test_a_smiling_photo_with_parted_lips_gives_a_closed_relaxed_mouth(smiling):
    photo, landmarks, posed, _ = smiling
    face = load_face()
    built, report = pf.face_from_photo(photo, landmarks)
    faps = report["expression_faps"]
    assert faps["open_jaw"] > 150 and faps["raise_l_cornerlip"] > 80 and faps["raise_r_cornerlip"] > 80
    rest_gap, rest_rise = _mouth(face.vertices, face)
    photo_gap, photo_rise = _mouth(posed, face)
    gap, rise = _mouth(built.vertices, face)
    assert photo_gap > 0.05 and photo_rise > 0.025  # what the photo shows: parted lips, raised corners
    assert abs(gap - rest_gap) < 0.003 and abs(rise - rest_rise) < 0.005  # closed and level, as at rest
    error = _aligned_error(built.vertices[face.parts["skin"]], face.vertices[face.parts["skin"]]) / _face_width(face)
    assert error.mean() < 0.008  # the smile is gone from the whole face (as photographed: 1.2%)


def test_the_photos_teeth_never_land_on_the_lips(smiling):
    """Between the photo's lips (teeth, the dark mouth) the texture is the lips' own colour, so
    the lips' texture, however it is filtered at their edge, never shows the teeth; the teeth,
    tongue and mouth keep the face's own materials."""
    from puppet.photo.texture import _inside_distance

    photo, landmarks, posed, project = smiling
    face = load_face()
    built, _ = pf.face_from_photo(photo, landmarks)
    rows, cols = np.mgrid[:SIZE, :SIZE]
    pixels = np.c_[cols.ravel(), rows.ravel()].astype(float)
    opening = _inside_distance(project(posed[face.contours["mouth_opening"]]), pixels) > 2.0  # a texel from the edge
    lips = (_inside_distance(project(posed[face.contours["vermilion_border"]]), pixels) > 1.0) & ~opening
    inside, lip = (photo.reshape(-1, 3)[m] / 255.0 for m in (opening, lips))
    assert opening.sum() > 200 and np.linalg.norm(np.median(inside, axis=0) - np.median(lip, axis=0)) > 0.15
    # where each photo pixel lies in the texture: the texture is the photo cut and scaled
    seen = built.texture_weight > 0
    to_texture = np.linalg.lstsq(np.c_[project(posed[seen]), np.ones(seen.sum())], built.uv[seen], rcond=None)[0]
    uv = np.c_[pixels[opening], np.ones(opening.sum())] @ to_texture
    h, w = built.texture.shape[:2]
    painted = built.texture[np.round((1 - uv[:, 1]) * (h - 1)).astype(int), np.round(uv[:, 0] * (w - 1)).astype(int)] / 255.0
    near_lip = np.abs(painted - np.median(lip, axis=0)).max(axis=1) < 0.12
    assert near_lip.mean() > 0.99  # the lips' colour (the texel map is fitted: a texel off at the edge)
    teeth_parts = np.concatenate([face.parts[p] for p in ("teeth_upper", "teeth_lower", "tongue")])
    assert built.texture_weight[teeth_parts].max() == 0


def test_the_photo_meets_the_skin_colour_round_the_head_without_a_seam(shot, fdp11):
    """A photo of a face with darker skin than the default's, lit from one side, brown hair down
    to above the brows and a black collar under the chin: the sides, back and neck take the
    photo's skin colour, and where the photo fades out it and the vertex colour agree."""
    photo, _ = shot
    face = load_face()
    side_light = np.linspace(0.55, 1.15, SIZE)[None, :, None]
    tinted = np.clip(photo.astype(float) * [0.62, 0.5, 0.42] * side_light, 0, 255).astype(np.uint8)
    points = dict(zip(fdp11.keys, fdp11.points))
    eyes, chin = points["3.12"][1], points["2.1"][1]
    tinted[: int(eyes - 0.35 * (chin - eyes))] = (90, 60, 35)  # hair
    tinted[int(chin + 0.02 * SIZE):] = (15, 15, 20)  # collar
    built, report = pf.face_from_photo(tinted, fdp11)
    tone = np.array(report["skin_tone"])
    back = face.parts["skin"][face.vertices[face.parts["skin"], 2] < face.pivots["head"][2]]
    back_colour = np.median(built.colors[back], axis=0)
    assert np.linalg.norm(back_colour - tone) < np.linalg.norm(np.median(face.colors[back], axis=0) - tone) / 3
    assert seam(built) < 0.08


def test_a_turned_head_photo_is_refused(egl):
    """MediaPipe still finds a face turned 60 degrees (its landmarks are projected here): it is
    refused as not frontal, naming the measure."""
    from puppet.view.renderer import Renderer

    face = load_face()
    with Renderer.for_face(face, width=SIZE, height=SIZE) as renderer:
        front = renderer.aim(face.vertices, view="front")
        turn = np.radians(60)
        distance = np.linalg.norm(front.eye - front.target)
        renderer.look_at(front.target + distance * np.array([np.sin(turn), 0.0, np.cos(turn)]), front.target)
        pixels = renderer.project(pf.mediapipe_points(face).on(face.vertices))
    with pytest.raises(pf.PhotoFaceError, match="not a frontal face: the nose tip is .* the head is turned"):
        pf.fit_photo(face, pf.parse_landmarks(pixels.tolist()), (SIZE, SIZE))


def test_the_picker_zooms_and_pans_and_moves_detected_mediapipe_points(shot, tmp_path):
    """The MediaPipe layout starts from detected points (here the default face's own, with a
    depth) and saves them moved, each keeping its depth; the page zooms and pans."""
    from puppet.view.renderer import save_png

    photo, project = shot
    face = load_face()
    save_png(photo, tmp_path / "photo.png")
    start = np.c_[project(pf.mediapipe_points(face).on(face.vertices)), np.linspace(-20.0, 20.0, 468)]
    with pytest.raises(pf.PhotoFaceError, match="moves detected points"):
        PickerServer(tmp_path / "photo.png", "mediapipe468", tmp_path / "points.json")
    picker = PickerServer(tmp_path / "photo.png", "mediapipe468", tmp_path / "points.json",
                          start={"layout": "mediapipe468", "points": start.tolist()})
    try:
        page = urllib.request.urlopen(picker.url, timeout=5).read().decode()
        assert "addEventListener('wheel'" in page and "zoom(" in page and "pointermove" in page
        served = json.loads(urllib.request.urlopen(picker.url + "start", timeout=5).read())
        assert np.allclose(served["points"], start)
        moved = start[:, :2].copy()
        moved[1] += (3.0, -2.0)  # the nose tip nudged
        request = urllib.request.Request(picker.url + "points", data=json.dumps({"points": moved.tolist()}).encode(),
                                         headers={"Content-Type": "application/json"}, method="POST")
        assert urllib.request.urlopen(request, timeout=5).status == 200
    finally:
        saved = picker.wait(timeout=5)
    landmarks = pf.read_landmarks(saved)
    assert landmarks.layout == "mediapipe468" and np.allclose(landmarks.points, moved)
    assert np.allclose(landmarks.depth, start[:, 2])


def test_the_focal_length_comes_from_exif_only_for_the_photo_as_taken(tmp_path):
    """A 35 mm-equivalent 50 mm lens on a 600 x 400 photo: 50 / 43.27 of its diagonal in pixels;
    once the photo is resized (its EXIF still says 600 x 400) the portrait default is used."""
    from PIL import Image

    from puppet.photo.depth import focal_from_exif

    exif = Image.Exif()
    exif.get_ifd(0x8769).update({0xA405: 50, 0xA002: 600, 0xA003: 400})
    Image.new("RGB", (600, 400)).save(tmp_path / "taken.jpg", exif=exif)
    Image.new("RGB", (300, 200)).save(tmp_path / "resized.jpg", exif=exif)
    Image.new("RGB", (600, 400)).save(tmp_path / "plain.png")
    assert focal_from_exif(tmp_path / "taken.jpg") == pytest.approx(50 * np.hypot(600, 400) / 43.27)
    assert focal_from_exif(tmp_path / "resized.jpg") is None and focal_from_exif(tmp_path / "plain.png") is None
