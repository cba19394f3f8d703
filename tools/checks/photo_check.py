"""An honest check of ``puppet face-from-photo`` on a face whose shape is known: the ICT face.

The ICT-FaceKit neutral head (read from ``../shared/assets/ict_facekit``, never copied) is
rendered frontally (``puppet.view.renderer``, its default portrait camera, a flat skin tone: ICT has no
colours). The face is built from that image with landmarks of these kinds:

* ``iBUG-68 exact 2D``: ICT's 68 iBUG landmark vertices projected with the render's camera;
* ``iBUG-68 exact 3D``: the same with their exact depth (as a perfect detector's ``z``);
* ``MediaPipe exact 2D`` / ``3D``: the points on ICT's surface where MediaPipe finds its 468
  landmarks (over nine views, as ``tools/builders/build_mediapipe_map.py`` finds them on the default
  face), projected exactly, without and with their exact depth: the automatic path with a
  perfect detector;
* ``MediaPipe detector``: MediaPipe run on the rendered image, as ``puppet face-from-photo``
  does with no ``--landmarks``: the automatic path as a user gets it; and the same with its
  depth trusted fully, to show what the detector's depth is worth here.

Exact depth is trusted fully (``depth_trust=1``); the detector's as the command does
(``puppet.photo.depth.DEPTH_TRUST``). Each row is built with the shape model and, for
comparison, without it (the warp alone). Each face is compared with ICT after a similarity alignment
(Umeyama) on the 68 landmarks, relative to the ICT face width (landmarks 0 to 16):

* at the landmarks: the built face's 68 points (``puppet.photo.build.ibug_points``: fixed points on the
  default face's mesh) against ICT's, in 3D and in the frontal plane (x, y);
* face area (the issue's measure): every skin vertex inside the face oval (frontal x, y) facing
  forward, its distance to ICT's face-area surface (vertices 0-9408);
* face area, visible: the same vertices less those hidden from the front (under the jaw, the
  mouth bag, the eye sockets: about a fifth of them, which no photo can shape and which sit far
  from ICT's face block, whose mouth and eyes are holes);
* the same after the best similarity of the two surfaces (iterative closest points from the
  landmark alignment): the shape alone, whatever the landmark conventions.

"Doing nothing" is the default face unchanged, measured the same way. Where the face-area error
comes from is split by region (``regions``, ``profile``). Also measured: how well
MediaPipe's depth matches ICT's at its landmarks, against the default face's (what
``puppet.photo.depth.DEPTH_TRUST`` rests on), and how a smile is taken out (``neutralised``). Writes docs/photo_face.md and docs/photo_face.png.
Needs the photo environment for the MediaPipe rows (they are skipped without it).
Run: PYTHONPATH=. .venv/bin/python tools/checks/photo_check.py
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image, ImageDraw
from scipy.spatial import cKDTree

from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.photo import build as pf
from puppet.photo.depth import DEPTH_TRUST, face_width, similarity_3d
from puppet.photo.detect import detect_landmarks, photo_python
from puppet.photo.texture import _inside_distance
from puppet.runtime.normals import VertexNormals
from puppet.view.renderer import Renderer, render_face, save_png

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: tools.* as packages
from tools.builders.build_mediapipe_map import cast, detected_on_surface  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
ICT = ROOT.parent / "shared" / "assets" / "ict_facekit"
FACE_AREA = 9409  # ICT vertices 0-9408 are the face block
SIZE = 800
MARGIN = 1.6
VIEWED = ("iBUG-68 exact 3D", "MediaPipe exact 3D", "MediaPipe detector")  # the built faces in photo_face_views.png
EXACT_NOISE = 0.001  # landmark error of exact projected points, face widths (puppet.photo.depth.LANDMARK_NOISE)


class Ict:
    """The ICT face, its render and its camera: exact pixels and depths of any of its points."""

    def __init__(self) -> None:
        self.face = load_face(ICT / "generic_neutral_mesh.obj")
        ids = json.loads((ICT / "vertex_indices.json").read_text())["idx_to_landmark_verts"]
        self.landmarks = self.face.vertices[ids]
        self.width = float(np.linalg.norm(self.landmarks[0] - self.landmarks[16]))
        self.surface = surface_tree(self.face)
        self.renderer = Renderer(self.face.triangles, len(self.face.vertices), None, width=SIZE, height=SIZE)
        self.camera = self.renderer.aim(self.face.vertices[:FACE_AREA], view="front", margin=MARGIN)
        self.photo = self.renderer.render(self.face.vertices)
        self.focal = SIZE / 2 / np.tan(np.radians(self.camera.fov) / 2)

    def exact(self, points: np.ndarray) -> np.ndarray:
        """(M, 3): each point's pixel and depth as a perfect detector would give them (pixel
        scale at the face, smaller is nearer, zero at their mean)."""
        distance = (points - self.camera.eye) @ -self.camera.basis()[2]
        reference = distance.mean()
        return np.c_[self.renderer.project(points), (distance - reference) * self.focal / reference]

    def mediapipe_points(self) -> np.ndarray:
        """Where MediaPipe finds its 468 landmarks on ICT's face block (468, 3)."""
        tris = self.face.triangles[(self.face.triangles < FACE_AREA).all(axis=1)]
        with tempfile.TemporaryDirectory() as work:
            found, _, _ = detected_on_surface(self.renderer, self.face.vertices, tris,
                                              self.face.vertices[:FACE_AREA], MARGIN, Path(work))
        return found


def surface_tree(ict: Face, samples: int = 400_000) -> cKDTree:
    """A k-d tree on points sampled evenly (by area, seeded) over ICT's face-area triangles:
    the nearest sample is the surface distance to within about 0.2% of the face width."""
    tris = ict.triangles[(ict.triangles < FACE_AREA).all(axis=1)]
    mesh = trimesh.Trimesh(ict.vertices, tris, process=False)
    points, _ = trimesh.sample.sample_surface(mesh, samples, seed=0)
    return cKDTree(points)


def face_area(face: Face) -> np.ndarray:
    """Skin vertices inside the face oval (frontal x, y) whose normal faces forward."""
    skin = face.parts["skin"]
    oval = face.vertices[face.contours["face_oval"], :2]
    normals = VertexNormals(face.triangles, len(face.vertices))(face.vertices)
    inside = _inside_distance(oval, face.vertices[skin, :2]) > 0
    return skin[inside & (normals[skin, 2] > 0)]


def visible(face: Face, rows: np.ndarray) -> np.ndarray:
    """The vertices of ``rows`` that a ray from the front reaches first."""
    skin = face.parts["skin"]
    corners = face.vertices[face.triangles[np.isin(face.triangles, skin).all(axis=1)]]
    front = face.vertices[:, 2].max() + 1.0
    seen = []
    for i in rows:
        hit, which = cast(np.array([*face.vertices[i, :2], front]), np.array([[0.0, 0.0, -1.0]]), corners)
        seen.append(which[0] >= 0 and hit[0, 2] - face.vertices[i, 2] < 1e-2)
    return rows[np.array(seen)]


def measure(face: Face, ict: Ict, ibug: pf.MeshPoints, area: np.ndarray, shown: np.ndarray) -> dict[str, float]:
    """Errors of ``face`` against ICT (module docstring), / ICT face width."""
    points = ibug.on(face.vertices)
    align = similarity_3d(points, ict.landmarks).apply
    at = align(points) - ict.landmarks
    out = {"landmarks_3d": np.linalg.norm(at, axis=1).mean(), "landmarks_xy": np.linalg.norm(at[:, :2], axis=1).mean()}
    moved = align(face.vertices)
    out["area"] = ict.surface.query(moved[area])[0].mean()
    out["area_visible"] = ict.surface.query(moved[shown])[0].mean()
    out["area_visible_surface_aligned"] = _icp(moved[shown], ict.surface)
    return {k: float(v) / ict.width for k, v in out.items()}


REGIONS = ("hidden: eye sockets", "hidden: mouth", "hidden: other", "outline band", "forehead", "nose", "eyes",
           "lower face")


def regions(face: Face, area: np.ndarray, shown: np.ndarray) -> np.ndarray:
    """A ``REGIONS`` name for each face-area vertex of the default face: hidden from the front
    (eye sockets, the mouth bag, the rest: under the nose and the jaw) or visible (a band of 8%
    of the width inside the face oval, then: forehead above the brows, the nose, the band of
    the eyes, the lower face), from its feature points."""
    v, fp = face.vertices[area], face.feature_points
    width = face_width(face)
    eyes, mouth = (fp["3.7"][1] + fp["3.12"][1]) / 2, fp["2.3"][1]
    edge = _inside_distance(face.vertices[face.contours["face_oval"], :2], v[:, :2]) < 0.08 * width
    hidden = ~np.isin(area, shown)
    near_eyes = np.abs(v[:, 1] - eyes) < 0.12 * width
    near_mouth = (np.abs(v[:, 1] - mouth) < 0.12 * width) & (np.abs(v[:, 0]) < 0.25 * width)
    nose = (v[:, 1] > fp["9.15"][1] - 0.02 * width) & (np.abs(v[:, 0]) < 0.12 * width)
    return np.select(
        [hidden & near_eyes, hidden & near_mouth, hidden, edge, v[:, 1] > min(fp["4.1"][1], fp["4.2"][1]),
         nose, v[:, 1] > eyes - 0.1 * width], list(REGIONS[:7]), REGIONS[7])


def profile(face: Face, ict: Ict, ibug: pf.MeshPoints, area: np.ndarray, labels: np.ndarray) -> dict[str, float]:
    """Where the face-area error of ``face`` comes from: each region's share of it (its vertices'
    distances summed over all the face area's vertices, / ICT face width: the shares add up to
    ``measure``'s face area)."""
    points = ibug.on(face.vertices)
    distance = ict.surface.query(similarity_3d(points, ict.landmarks).apply(face.vertices[area]))[0]
    return {name: float(distance[labels == name].sum() / len(area) / ict.width) for name in REGIONS}


def _icp(points: np.ndarray, surface: cKDTree, rounds: int = 30) -> float:
    """Mean distance of ``points`` to the surface after the best similarity (iterative closest
    points, the worst tenth left out of each step)."""
    moved = points
    for _ in range(rounds):
        distance, nearest = surface.query(moved)
        keep = distance < np.percentile(distance, 90)
        moved = similarity_3d(points[keep], surface.data[nearest[keep]]).apply(points)
    return float(surface.query(moved)[0].mean())


def depth_accuracy(ict: Ict, base: Face, on_ict: np.ndarray, detected: np.ndarray) -> dict[str, float]:
    """RMS depth error at MediaPipe's landmarks (/ ICT face width) after each is brought onto
    ICT's true points by a similarity: MediaPipe's own depth, the default face's, and the blend
    ``face-from-photo`` makes of them (``DEPTH_TRUST``)."""
    model = pf.mediapipe_points(base).on(base.vertices)
    camera = pf.PhotoCamera(ict.focal, np.array([SIZE / 2, SIZE / 2]))
    lifted = camera.lift(detected[:, :2], -(detected[:, 2] - detected[:, 2].mean()))
    truth = (on_ict - ict.camera.eye) @ ict.camera.basis().T  # camera frame: x right, y up, z back
    into_model = similarity_3d(lifted, model).apply(lifted)
    blend = np.c_[into_model[:, :2], DEPTH_TRUST * into_model[:, 2] + (1 - DEPTH_TRUST) * model[:, 2]]
    out = {}
    for name, shape in (("mediapipe", into_model), ("default face", model), (f"blend ({DEPTH_TRUST} mediapipe)", blend)):
        error = similarity_3d(shape, truth).apply(shape) - truth
        out[name] = float(np.sqrt((error[:, 2] ** 2).mean()) / ict.width)
    return out


def neutralised(base: Face) -> str:
    """The default face smiling with its jaw open (FAP 2 joy, open_jaw 250), rendered frontally
    with a long lens, its MediaPipe points projected with their exact depth, built again: the
    lips' gap and the corners' rise above the lips' middle (/ face width), at rest, in the photo
    and built; the expression measured; the built skin's mean distance to the default's."""
    from puppet.runtime.runtime import Runtime

    posed = Runtime(base).deform_faps({"open_jaw": 250}, expression=(1, 63, 0, 0))
    with Renderer.for_face(base, width=512, height=512) as renderer:
        camera = renderer.aim(base.vertices, view="front", fov=8.0)
        points = pf.mediapipe_points(base).on(posed)
        distance = (points - camera.eye) @ -camera.basis()[2]
        focal = 256 / np.tan(np.radians(camera.fov) / 2)
        depth = (distance - distance.mean()) * focal / distance.mean()
        landmarks = pf.parse_landmarks(np.c_[renderer.project(points), depth].tolist())
        built, report = pf.face_from_photo(renderer.render(posed), landmarks)
    width = face_width(base)
    fv = base.feature_vertices

    def mouth(v: np.ndarray) -> str:
        upper, lower, left, right = (v[fv[k], 1] for k in ("2.2", "2.3", "2.4", "2.5"))
        return f"gap {100 * (upper - lower) / width:.2f}%, corners {100 * ((left + right) - (upper + lower)) / 2 / width:+.2f}%"

    skin = base.parts["skin"]
    error = np.linalg.norm(similarity_3d(built.vertices[skin], base.vertices[skin]).apply(built.vertices[skin])
                           - base.vertices[skin], axis=1).mean() / width
    faps = ", ".join(f"{k} {v:.0f}" for k, v in report["expression_faps"].items() if abs(v) >= 50)
    return (f"Smiling default face (joy, open_jaw 250) built again: at rest {mouth(base.vertices)}; in the photo "
            f"{mouth(posed)}; built {mouth(built.vertices)}; skin {100 * error:.2f}% from the default's (aligned); "
            f"measured {faps}.")


def main() -> int:
    if not (ICT / "generic_neutral_mesh.obj").is_file():
        print(f"ICT face not found under {ICT}: skipped")
        return 0
    ict = Ict()
    base = load_face()
    ibug = pf.ibug_points(base)
    area = face_area(base)
    shown = visible(base, area)
    exact_ibug = ict.exact(ict.landmarks)
    exact = {"landmark_noise": EXACT_NOISE}
    builds = {"iBUG-68 exact 2D": (exact_ibug[:, :2], exact),
              "iBUG-68 exact 3D": (exact_ibug, exact | {"depth_trust": 1.0})}
    depth = None
    if photo_python() is not None:
        on_ict = ict.mediapipe_points()
        builds["MediaPipe exact 2D"] = (ict.exact(on_ict)[:, :2], exact)
        builds["MediaPipe exact 3D"] = (ict.exact(on_ict), exact | {"depth_trust": 1.0})
        with tempfile.TemporaryDirectory() as work:
            save_png(ict.photo, Path(work) / "ict.png")
            detected = np.array(detect_landmarks(Path(work) / "ict.png")["points"])
        builds["MediaPipe detector, its depth trusted fully"] = (detected, {"depth_trust": 1.0})
        builds["MediaPipe detector"] = (detected, {})
        depth = depth_accuracy(ict, base, on_ict, detected[:468])
    else:
        print("no photo environment (tools/setup.sh): the MediaPipe rows are skipped")
    rows = {"doing nothing (generic face)": measure(base, ict, ibug, area, shown)}
    labels = regions(base, area, shown)
    profiles = {"doing nothing (generic face)": profile(base, ict, ibug, area, labels)}
    warp_only = dict(rows)
    fits = {}
    for name, (points, options) in builds.items():
        landmarks = pf.parse_landmarks(points.tolist())
        fits[name] = pf.fit_photo(base, landmarks, (SIZE, SIZE), **options)
        rows[name] = measure(fits[name].face(), ict, ibug, area, shown)
        profiles[name] = profile(fits[name].face(), ict, ibug, area, labels)
        without = pf.fit_photo(base, landmarks, (SIZE, SIZE), shape=False, **options)
        warp_only[name] = measure(without.face(), ict, ibug, area, shown)
    table, without_model, where = _table(rows), _table(warp_only), _profile_table(profiles, labels)
    print(table)
    print("without the shape model (the warp alone):\n" + without_model)
    print("where the face-area error comes from:\n" + where)
    if depth:
        print("depth RMS at MediaPipe's landmarks: " + ", ".join(f"{k} {100 * v:.2f}%" for k, v in depth.items()))
    smile = neutralised(base)
    print(smile)
    last = list(fits)[-1]
    docs = ROOT / "docs"
    save_png(figure(ict.photo, builds[last][0], fits[last]), docs / "photo_face.png")
    save_png(views(ict.face, base, {k: v for k, v in fits.items() if k in VIEWED}), docs / "photo_face_views.png")
    (docs / "photo_face.md").write_text(_report(table, without_model, where, depth, smile, last, fits[last].report),
                                        encoding="utf-8")
    ict.renderer.release()
    return 0


def figure(photo: np.ndarray, points: np.ndarray, fit: pf.PhotoFit) -> np.ndarray:
    """The photo with the landmarks (red) and the built face's contours as photographed
    (green); the built face textured; its shape untextured."""
    overlay = Image.fromarray(photo)
    draw = ImageDraw.Draw(overlay)
    posed = fit.face(posed=True)
    for name in ("face_oval", "vermilion_border", "mouth_opening", "left_lid_opening", "right_lid_opening"):
        loop = fit.pixels(posed.vertices[posed.contours[name]])
        draw.line([tuple(p) for p in np.vstack([loop, loop[:1]])], fill=(40, 220, 60), width=2)
    for x, y in points[:, :2]:
        draw.ellipse((x - 1.5, y - 1.5, x + 1.5, y + 1.5), fill=(230, 40, 40))
    textured, _ = pf.face_from_photo(photo, pf.parse_landmarks(points.tolist()), "ict")
    panels = [np.asarray(overlay), render_face(textured, width=SIZE, height=SIZE),
              render_face(_untextured(textured), width=SIZE, height=SIZE)]
    return np.concatenate(panels, axis=1)


def views(ict: Face, base: Face, fits: dict[str, pf.PhotoFit], size: int = 320) -> np.ndarray:
    """Rows: ICT, the generic face, then each built face (untextured); columns: front,
    three-quarter, profile. Each face framed on itself."""
    faces = [ict, base] + [fit.face() for fit in fits.values()]
    rows = [np.concatenate([render_face(_untextured(face), width=size, height=size, view=view)
                            for view in ("front", "three_quarter", "profile")], axis=1) for face in faces]
    return np.concatenate(rows, axis=0)


def _untextured(face) -> Face:
    return Face(face.name, face.vertices, face.triangles, face.parts, colors=None)


def _table(rows: dict[str, dict[str, float]]) -> str:
    generic = next(iter(rows.values()))
    head = ("| landmarks | 3D landmarks | x,y landmarks | face area (issue's) | face area, visible | "
            "visible, surfaces aligned |\n|---|---|---|---|---|---|\n")
    body = ""
    for name, m in rows.items():
        cells = [f"{100 * v:.2f}%" + ("" if m is generic else f" ({v / generic[k]:.2f}x)") for k, v in m.items()]
        body += f"| {name} | " + " | ".join(cells) + " |\n"
    return head + body


def _profile_table(profiles: dict[str, dict[str, float]], labels: np.ndarray) -> str:
    head = ("| face | " + " | ".join(f"{name} ({np.mean(labels == name):.0%})" for name in REGIONS) + " |\n|---|"
            + "---|" * len(REGIONS) + "\n")
    return head + "".join(f"| {face} | " + " | ".join(f"{100 * share[name]:.2f}%" for name in REGIONS) + " |\n"
                          for face, share in profiles.items())


def _report(table: str, without_model: str, where: str, depth: dict | None, smile: str, last: str, report: dict) -> str:
    frontal = ", ".join(f"{k} {v:.3f}" for k, v in report["frontal"].items())
    depth_line = ("MediaPipe's depth against ICT's at its own landmarks (RMS after a similarity, / face width): "
                  + ", ".join(f"{k} {100 * v:.2f}%" for k, v in depth.items()) + ".") if depth else \
        "(No photo environment: the MediaPipe rows and the depth figures were skipped.)"
    return f"""# A face from one frontal photo: checked on the ICT face

`tools/checks/photo_check.py` renders the ICT-FaceKit neutral head frontally ({SIZE}x{SIZE}, the
renderer's portrait camera, flat skin tone), builds the face from that image
(`puppet.photo.build`) with landmarks of several kinds, and compares it with the ICT mesh after a
similarity alignment on ICT's 68 iBUG landmarks. Errors are relative to the ICT face width
(landmark 0 to 16); in brackets, the ratio to doing nothing.

* iBUG-68 exact 2D / 3D: ICT's 68 landmark vertices projected with the render's camera, without
  and with their exact depth.
* MediaPipe exact 2D / 3D: the points of ICT's surface where MediaPipe finds its 468 landmarks
  (over nine views), projected exactly, without and with their depth: the automatic path with a
  perfect detector.
* MediaPipe detector: MediaPipe on the rendered image, as `puppet face-from-photo` runs it (its
  depth trusted `puppet.photo.depth.DEPTH_TRUST`); and the same with its depth trusted fully.

Every face is shaped by the shape model (`puppet.photo.shapemodel`, MakeHuman's CC0 shape
targets) and then warped onto the landmarks; the second table is the warp alone, as before the
model.

Measures: the built face's 68 points (fixed points of the default face's mesh) against ICT's;
"face area (issue's)": every skin vertex inside the face oval facing forward, its distance to
ICT's face-area surface; "visible": the same less the vertices hidden from the front (under the
jaw, the mouth bag, the eye sockets), which dominated the issue's measure (its 90th percentile
was 14% of the face width); "surfaces aligned": the visible measure after the best similarity
of the two surfaces, which leaves out how the landmark conventions differ.

{table}
Without the shape model (the warp alone):

{without_model}
Where the face-area error comes from (`regions`: each region's share of the issue's face-area
figure, so a row adds up to it; in brackets, the region's share of the face area's vertices):

{where}
{depth_line}

The expression taken out (`neutralised`): {smile}

Fit of the last row ({last}): similarity residual {report['similarity_residual']:.3f} eye widths;
frontal measures: {frontal}; head turned {', '.join(f"{k} {v:+.1f}" for k, v in report['head_degrees'].items())}
degrees; expression measured (FAPU): {report['expression_faps'] or 'none'}.

![photo with MediaPipe's landmarks (red) and the built face's contours as photographed (green);
the built face textured; its shape](photo_face.png)

What it shows and what it does not:

* Depth is what moves the issue's measure, and most of what is left of it no photo shows. With
  exact depth MediaPipe's 468 points and the shape model bring the face area closest to ICT;
  from x and y alone, even exact ones, the face area gains nothing on doing nothing: a frontal
  photo fixes the face across, and ICT's depth is not what MakeHuman's faces of that width and
  height have. Of the exact 3D row's face-area error, the hidden vertices (eye sockets behind
  the eyeballs, the mouth bag, under the nose and jaw) are most: ICT's face block has holes
  there, so their distance is how deep the default face's sockets and mouth bag sit behind
  ICT's lids and lips.
* MediaPipe's depth on this render is further from ICT's than the default face's own (the depth
  line above). On renders of held-out MakeHuman faces it errs 3.9% of the face width against
  true depths about 1% from the default face's (`tools/checks/shape_check.py`), and trusting it 0.3
  made those faces worse than the generic one, so the command trusts it
  `puppet.photo.depth.DEPTH_TRUST`. Here, trusted fully, it helps the eye sockets and hurts the
  face's outline and forehead (the row above the last).
* The iBUG landmark convention is not MediaPipe's: ICT's brow and jaw landmark vertices sit
  elsewhere than where MediaPipe finds brows and jaw on an untextured face (ICT's brow vertices
  are about 5% of the face width above them), so the 3D landmark error of the MediaPipe rows
  measures that difference as much as the face.
* With iBUG landmarks only, nothing is known above the brows: pulling the brows up to ICT's
  higher ones moves the default forehead with them, in front of ICT's.

* The faces built with exact depth show a crease in front of the ears, with the shape model and
  without it (the warp alone has it too): the warp takes the side of the face onto the
  landmarks while its anchors hold the back of the head still (`puppet.photo.depth.ANCHORS`).
  The detector's face, its depth barely trusted, has none.

![ICT, the generic face, then the faces built from iBUG-68 exact 3D, MediaPipe exact 3D and
the MediaPipe detector (untextured): front, three-quarter, profile](photo_face_views.png)
"""


if __name__ == "__main__":
    sys.exit(main())
