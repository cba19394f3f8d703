"""Landmarks found on a mesh by themselves: the head rendered from a few sides, MediaPipe's
landmarks found on the renders, lifted back onto the surface, turned into the MPEG-4 feature
points ``puppet rig`` needs.

1. **Which way is the face?** A mesh file says nothing about it. The mesh is rendered from its
   +z side first (the front of glTF, OBJ heads, MediaPipe's canonical face and ICT), upright
   (+y up) and rolled by quarter turns, and upright framed on its top (``HEAD_SHARE``: the head
   of a standing figure); when MediaPipe finds no face in those 5, the 20 other axis-aligned
   turns are rendered and searched in one run (``ORIENTATIONS``: 25 renders at most).
   The landmarks found in a turn are lifted (below) and fitted to where MediaPipe finds the same
   landmarks on the default face (``data/mediapipe_map.json``, in the face frame): the fit's
   rotation is a face frame, however the mesh was turned in its file, by right angles or not.
2. **The views.** In each face frame found (two, typically: MediaPipe also finds an upside-down
   face, labelled as if upright), the face, framed on its landmarks, is rendered from the front
   and turned (``VIEWS``: yaw +-25 degrees, pitch +-10 degrees), lit and painted as
   ``Renderer.for_face`` draws it (skin tone where the mesh has no colours, which MediaPipe takes
   for a face), and MediaPipe runs once over all of them (``puppet.photo.detect``). The frame
   whose front view fits the default face best is the face's.
3. **The lift.** Beside each render, a pass of its own writes every pixel's surface point (the
   mesh's position, interpolated: what unprojecting the depth buffer gives, without its precision
   loss); a landmark's pixel reads its 3D point there. Each lift is snapped to the nearest skin
   vertex (the skin: the connected component most landmarks land on). A landmark is taken from
   the views that see its surface within ``MIN_FACING`` of head-on (when none does: a feature
   point from all that see it, another landmark from the most frontal one): of their vertices,
   the one nearest all their lifts (a medoid: it stays on the surface). No two feature points
   share a vertex (``_distinct``).
   **The eyes**: a bare mesh's eyes render skin-coloured, and MediaPipe can see a slit under them
   (on a shape-model face, the upper lids on the lower lid). The lids' middles and the eye corners
   are taken from the eye opening's edge instead, where the front view of the skin alone sees
   through the lids (``_lid_edges``): on the two shape-model faces of ``transfer_check.py --found``
   the transfer's residual went from 0.421 / 0.414 to 0.396 / 0.393 (from the given landmarks:
   0.351 / 0.358).
4. **Feature points.** MediaPipe landmark -> FDP as ``face-from-photo`` reads them
   (``puppet.photo.build.MEDIAPIPE_FDP``: eye corners and lids, brows, nose, lips), and the
   default face's other feature points (chin, lid creases, jaw line, cheeks, ears, hairline)
   carried over by the warp all the landmarks make (``puppet.photo.carriedpoints``; the chin and
   the lid creases because the default face puts them elsewhere than MediaPipe: ``OWN_PLACE``):
   the {FDP id: vertex} landmark dict ``puppet.face.landmarks.apply_landmarks`` takes.

How sure: the views the face was found in, and the agreement between views, per feature point
the median distance of its lifts from the chosen vertex, in % of the face's width (between
MediaPipe's face-side points 234 and 454; for the lids and corners taken from the eye opening,
how far MediaPipe's own lie from them). A mesh where no view shows a face is refused in one
line (``DetectionError``). On the default face, ICT-FaceKit and MediaPipe's canonical face, the
points found lie within 2-2.5% of the face width of the given ones (median;
``tools/checks/landmark_accuracy.py``).
"""

from __future__ import annotations

import itertools
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import moderngl
import numpy as np
from PIL import Image
from scipy.spatial import cKDTree

from puppet.face.landmarks import FDP_NEEDED, apply_landmarks
from puppet.face.meshparts import components
from puppet.face.model import Face
from puppet.photo.build import MEDIAPIPE_FDP
from puppet.photo.carriedpoints import FACE_SIDES, carried_points, found_fdps, mediapipe_reference
from puppet.photo.detect import DetectionError, detect_faces
from puppet.runtime.normals import VertexNormals
from puppet.view.renderer import Camera, Renderer

SIZE = 640  # pixels, square renders
VIEWS = {"front": (0.0, 0.0), "left": (25.0, 0.0), "right": (-25.0, 0.0), "above": (0.0, 10.0), "below": (0.0, -10.0)}
"""View name -> (yaw, pitch) in degrees, turned about the face frame's y and x axes."""
FOV = 20.0  # degrees, vertical
FACE_SHARE = 0.55  # of the image's height the face's landmarks span in the views
FIND_SHARE = 0.85  # of the image the whole mesh spans in the search for the face
HEAD_SHARE = 0.15  # of a mesh's height (+y) its top is, framed too: the head of a standing figure
SAME_FRAME = 30.0  # degrees: face frames closer than this are one
MIN_FACING = 0.5  # cos of the angle between a lift's surface normal and the view: under it, seen too obliquely
N_MESH = 468  # MediaPipe's mesh landmarks (478 with the irises, which are not used)


def _orientations() -> list[np.ndarray]:
    """The 24 axis-aligned rotations (file -> face frame): the identity, then the quarter turns
    about z (the file's front kept), then the others."""
    turns = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            r = np.zeros((3, 3))
            r[np.arange(3), perm] = signs
            if np.linalg.det(r) > 0:
                turns.append(r)
    return sorted(turns, key=lambda r: (-r[2, 2], -np.trace(r)))


ORIENTATIONS = _orientations()


@dataclass
class FoundLandmarks:
    """What was found on a mesh: the FDP landmarks and how sure they are."""

    fdp: dict[str, int]  # FDP id -> vertex index (file order): ``--landmarks`` JSON; found and carried
    vertices: np.ndarray  # (468,) the vertex each MediaPipe landmark was snapped to, -1 where not seen
    spread: dict[str, float]  # FDP id -> agreement between views, in face widths (the points found)
    views_found: int  # views MediaPipe found the face in
    views: int  # views rendered (the search for the face's orientation included)
    rotation: np.ndarray  # (3, 3) file -> face frame, as the landmarks fitted it
    face_width: float  # mesh units

    def summary(self) -> str:
        """One line: how many points, in how many views, how well the views agree, how many carried."""
        spread = np.array(list(self.spread.values())) * 100
        worst = max(self.spread, key=self.spread.get)
        return (f"found {len(self.spread)} feature points in {self.views_found} of {len(VIEWS)} views "
                f"({self.views} rendered); views agree within {np.median(spread):.1f}% of the face width "
                f"(median; worst {spread.max():.1f}% at FDP {worst}); {len(self.fdp) - len(self.spread)} "
                "more carried from the default face")

    def errors(self, vertices: np.ndarray, given: dict[str, int]) -> dict[str, float]:
        """Per FDP found and in ``given`` ({FDP id: vertex}, landmarks known otherwise), the distance
        between the found and the given vertex of ``vertices`` (the mesh's), in face widths."""
        v = np.asarray(vertices, float)
        return {f: float(np.linalg.norm(v[self.fdp[f]] - v[given[f]])) / self.face_width
                for f in sorted(set(self.fdp) & set(given))}

    def error_summary(self, vertices: np.ndarray, given: dict[str, int]) -> str:
        """``errors`` in a line: over how many FDPs, the median, the largest and the worst five (%)."""
        error = {f: e * 100 for f, e in self.errors(vertices, given).items()}
        values = np.array(list(error.values()))
        worst = sorted(error, key=error.get, reverse=True)[:5]
        return (f"over {len(error)} FDPs, % of face width: median {np.median(values):.1f}, max {values.max():.1f}; "
                f"worst {', '.join(f'{f} {error[f]:.1f}' for f in worst)}")


def find_landmarks(face: Face, name: str, *, size: int = SIZE, keep: str | Path | None = None,
                   step: Callable[[str], None] | None = None) -> FoundLandmarks:
    """The FDP landmarks of the mesh ``face`` (file coordinates, as ``load_mesh`` gives it),
    found on its renders (module docstring); ``name`` names it in messages. ``keep``: a folder to
    leave the renders in (BMP), to look at. Raises ``DetectionError`` when no view shows a face."""
    say = step or (lambda text: None)
    with tempfile.TemporaryDirectory(prefix="puppet-marks-") as scratch, Shots(face, size) as shots:
        folder = Path(keep) if keep is not None else Path(scratch)
        folder.mkdir(parents=True, exist_ok=True)
        frames, tried = _find_face(shots, folder, name, say)
        rotation, lifts, facing, found, front = _views(shots, folder, name, frames)
        return _combine(face, shots.normals, lifts, facing, found, tried + len(VIEWS) * len(frames), rotation, name,
                        lambda skin: (front, shots.skin_surface(front, skin)))


def found_face(mesh: Face, name: str, *, step: Callable[[str], None] | None = None) -> tuple[Face, FoundLandmarks]:
    """The mesh ``mesh`` (``load_mesh``'s) made rig-ready from the landmarks found on it, as
    ``puppet rig`` does without ``--landmarks``, and those landmarks."""
    found = find_landmarks(mesh, name, step=step)
    return apply_landmarks(mesh, found.fdp), found


def _find_face(shots: Shots, folder: Path, name: str,
               say: Callable[[str], None]) -> tuple[list[tuple[np.ndarray, np.ndarray]], int]:
    """(the face frames the face may be in: (file -> face rotation, the landmarks lifted onto the
    mesh), how many renders it took): the file's front (+z) turned about it a quarter at a time
    and its top framed alone first, then the 20 other right-angle turns in one run. Every turn that shows a face gives a
    frame (its landmarks fitted to the default face's, ``_fit``) unless it lies within
    ``SAME_FRAME`` of a better fitting one. MediaPipe finds an upside-down face too, labelled as if
    upright, and seen askew a face may fit worse than upside down (30 degrees off: 0.11 against
    0.06 face widths): the frames left are told apart by ``_views``, seen straight on."""
    tried = 0
    for turns in (ORIENTATIONS[:4], ORIENTATIONS[4:]):
        if tried:
            say(f"no face with +z to the front: trying the mesh's {len(turns)} other right-angle turns")
        cameras = [shots.framing(turn, shots.vertices, FIND_SHARE) for turn in turns]
        if not tried:
            top = shots.vertices[:, 1] >= shots.vertices[:, 1].max() - HEAD_SHARE * np.ptp(shots.vertices[:, 1])
            cameras.append(shots.framing(turns[0], shots.vertices[top], FIND_SHARE))
            turns = [*turns, turns[0]]
        found, lifts = shots.detect(cameras, folder, f"find{tried:02d}-", name)
        tried += len(cameras)
        fits = sorted((fit for landmarks, (points, _) in zip(found, lifts) if landmarks
                       for fit in [_fit(points)] if fit is not None), key=lambda fit: fit[0])
        frames: list[tuple[np.ndarray, np.ndarray]] = []
        for _, rotation, points in fits:
            if all(_angle(rotation, other) > SAME_FRAME for other, _ in frames):
                frames.append((rotation, points))
        if frames:
            return frames, tried
    raise DetectionError(f"no face found in {tried} rendered views of {name}: its {len(ORIENTATIONS)} right-angle "
                         "turns, seen from the front; is it a face, with eyes, nose and mouth? "
                         "(or give its --landmarks)")


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle between two rotations, degrees."""
    return float(np.degrees(np.arccos(np.clip((np.trace(a @ b.T) - 1) / 2, -1.0, 1.0))))


def _fit(points: np.ndarray) -> tuple[float, np.ndarray, np.ndarray] | None:
    """(the residual, the rotation, the points) of the landmarks lifted in a view fitted to where
    MediaPipe finds them on the default face (``data/mediapipe_map.json``, face frame: similarity,
    RMS in face widths); None when fewer than half were lifted."""
    model = mediapipe_reference()
    seen = np.isfinite(points[:N_MESH]).all(axis=1)
    if seen.sum() < N_MESH // 2:
        return None
    p, q = points[:N_MESH][seen], model[seen]
    rotation = fit_rotation(p, q)
    turned, q = (p - p.mean(axis=0)) @ rotation.T, q - q.mean(axis=0)
    scale = (turned * q).sum() / (turned ** 2).sum()
    rms = np.sqrt(((scale * turned - q) ** 2).sum(axis=1).mean())
    return float(rms / np.linalg.norm(model[FACE_SIDES[0]] - model[FACE_SIDES[1]])), rotation, points


def fit_rotation(points: np.ndarray, model: np.ndarray) -> np.ndarray:
    """The rotation (no reflection) that best turns ``points`` onto their counterparts ``model``
    in the face frame, up to shift and scale (Procrustes): file -> face frame."""
    p, q = points - points.mean(axis=0), model - model.mean(axis=0)
    u, _, vt = np.linalg.svd(q.T @ p)
    return u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt


def project(camera: Camera, points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Pixel coordinates (M, 2), (column, row) with row 0 at the top, of ``points`` seen by ``camera``
    in an image of ``size`` (width, height)."""
    clip = camera.projection_matrix(size[0] / size[1]) @ camera.view_matrix() @ np.c_[points, np.ones(len(points))].T
    ndc = clip[:2] / clip[3]
    return np.stack([(ndc[0] + 1.0) / 2.0 * size[0], (1.0 - ndc[1]) / 2.0 * size[1]], axis=1)


def _views(shots: Shots, folder: Path, name: str, frames: list[tuple[np.ndarray, np.ndarray]]
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Camera]:
    """The face seen in each of ``VIEWS`` in each of the ``frames``, framed on its landmarks (one
    detector run), and of the frames the one whose front view's landmarks fit the default face's
    best (``_fit``): (its rotation, the landmarks lifted per view (V, 468, 3), facing (V, 468): cos
    of the surface's angle to the view, whether each view found the face (V,), its front view's camera)."""
    cameras = []
    for rotation, first in frames:
        face_points = first[:N_MESH][np.isfinite(first[:N_MESH]).all(axis=1)]
        cameras += [shots.framing(rotation, face_points, FACE_SHARE, yaw, pitch) for yaw, pitch in VIEWS.values()]
    found, lifts = shots.detect(cameras, folder, "view", name)
    n = len(VIEWS)
    fits = [_fit(lifts[k * n][0]) if found[k * n] else None for k in range(len(frames))]
    best = min(range(len(frames)), key=lambda k: np.inf if fits[k] is None else fits[k][0])
    views = slice(best * n, best * n + n)
    points = np.stack([p[:N_MESH] for p, _ in lifts[views]])
    facing = np.stack([f[:N_MESH] for _, f in lifts[views]])
    rotation = frames[best][0] if fits[best] is None else fits[best][1]
    return rotation, points, facing, np.array(found[views], dtype=bool), cameras[best * n]


def _combine(face: Face, normals: np.ndarray, lifts: np.ndarray, facing: np.ndarray, found: np.ndarray, views: int,
             rotation: np.ndarray, name: str,
             front: Callable[[np.ndarray], tuple[Camera, np.ndarray]]) -> FoundLandmarks:
    """Per landmark, the skin vertex its views agree on (module docstring, 3), the lids' middles
    and the eye corners moved onto the eye opening's edge (``_lid_edges``; ``front(skin)``: the
    front view's camera and the surface points of the skin alone it sees), and the FDPs."""
    if not found.any():
        raise DetectionError(f"no face found in {len(VIEWS)} rendered views of {name} turned to face the camera")
    vertices = np.asarray(face.vertices, float)
    skin = skin_vertices(vertices, face.triangles, lifts[found])
    rows = _lip_rows(vertices, normals, skin, rotation)
    chosen = np.full(N_MESH, -1)
    spread = np.full(N_MESH, np.nan)
    on_skin = _on_skin(vertices, skin, lifts)
    for i in range(N_MESH):
        use = _views_used(found & np.isfinite(lifts[:, i]).all(axis=1), on_skin[:, i], facing[:, i],
                          i in MEDIAPIPE_FDP)
        if not use.any():
            continue
        among, tree = _row(rows, MEDIAPIPE_FDP.get(i))
        near = among[tree.query(lifts[use, i])[1]]
        cost = np.linalg.norm(vertices[near][:, None] - lifts[use, i][None], axis=2).sum(axis=1)
        chosen[i] = near[np.argmin(cost)]
    _lid_edges(chosen, vertices, normals, skin, *front(skin))
    _apart(chosen, vertices, rows, lifts, found, rotation[1])
    _outside(chosen, vertices, rows[None], lifts, found, rotation[0])
    _distinct(chosen, vertices, rows, lifts, found)
    _apart(chosen, vertices, rows, lifts, found, rotation[1])  # a point set apart can cross its pair
    for i in np.flatnonzero(chosen >= 0):  # over the views the choice used
        use = _views_used(found & np.isfinite(lifts[:, i]).all(axis=1), on_skin[:, i], facing[:, i],
                          i in MEDIAPIPE_FDP)
        spread[i] = np.median(np.linalg.norm(lifts[use, i] - vertices[chosen[i]], axis=1))
    taken = found_fdps()
    missing = sorted({taken[i] for i in taken if chosen[i] < 0} & set(FDP_NEEDED))
    if missing:
        raise DetectionError(f"{name}: the face was found but FDP(s) {missing} were seen in no view "
                             "(give its --landmarks, or correct them: puppet pick-landmarks)")
    fdp = {fid: int(chosen[i]) for i, fid in sorted(taken.items(), key=lambda kv: kv[1]) if chosen[i] >= 0}
    sides = chosen[list(FACE_SIDES)]
    width = float(np.linalg.norm(np.subtract(*vertices[sides])) if (sides >= 0).all()
                  else np.ptp(vertices[list(fdp.values())] @ rotation[0]))  # else the feature points' span
    agree = {taken[i]: float(spread[i] / width) for i in taken if chosen[i] >= 0}
    fdp |= carried_points(vertices, skin, chosen, list(fdp.values()))
    return FoundLandmarks(fdp=fdp, vertices=chosen, spread=agree, views_found=int(found.sum()),
                          views=views, rotation=rotation, face_width=width)


def _views_used(seen: np.ndarray, on_skin: np.ndarray, facing: np.ndarray, feature: bool) -> np.ndarray:
    """The views a landmark is taken from (module docstring, 3), of those that ``seen`` it: the ones
    that lift it onto the skin where any does (``_on_skin``), and of those the ones that see its
    surface within ``MIN_FACING`` of head-on, else all of them for a ``feature`` point (an FDP),
    the most frontal for another landmark. All False where none saw it.

    A feature point no view sees head-on is a lip corner in its crease: taken from the most
    frontal view alone, on a shape-model face (seen at most 0.48 head-on) it came from a view
    turned 25 degrees that saw the upper lip in front of it, the inner corner 2.5 fell on 2.2's
    vertex (21% of the face width off) and the rig refused the face; among all the views, such a
    view is outvoted (7% off). The other landmarks seen so are the face oval's, seen edge-on,
    which only feed the warp (``carriedpoints``): from all the views they spread over each view's
    outline, and MediaPipe's canonical face's carried jaw angles moved from 18% to 26% off."""
    if (seen & on_skin).any():
        seen = seen & on_skin
    if not seen.any():
        return seen
    use = seen & (facing >= MIN_FACING)
    if use.any() or feature:
        return use if use.any() else seen
    return seen & (facing == facing[seen].max())


EYES = ((386, 374, 263, 362), (159, 145, 33, 133))
"""Per eye, MediaPipe's upper and lower lid middles (3.1 / 3.3, 3.2 / 3.4) and its corners."""
MIN_GAP = 2  # pixels: a gap between the lids thinner than this in the front view is no eye opening
DEPTH_WEIGHT = 0.25  # of a distance along the view, near a lid's edge: the lid's thickness lies along it
DEEP = 0.3  # eye widths behind the lids: a surface seen so far behind, through the opening, is not a lid


def _lid_edges(chosen: np.ndarray, vertices: np.ndarray, normals: np.ndarray, skin: np.ndarray, camera: Camera,
               surface: np.ndarray) -> None:
    """The lid middles and eye corners moved onto the eye opening's edge (in place). On a bare
    mesh the eyes render skin-coloured; on a shape-model face MediaPipe saw a slit under the eye
    and put the lids and corners there (the upper lids 8-9% of the face width low, on the lower
    lid; the corners 3-5%), and the transfer's residual was 0.41 (0.36 from the given landmarks).

    The eye opening is where the front view of the skin alone (``camera``; ``surface``: the skin's
    points per pixel) sees nothing (a hole) or a surface ``DEEP`` behind the lids (the socket
    behind the eyeball, the inside of the head), through them (``_gaps``); not where the whole mesh
    shows the eyeball, which pokes through the upper lid on those faces (its edge lay 3.5-5% of the
    face width above the lid's; painted for MediaPipe, it drew the lids there too). In the pixel
    column midway between the corners found (MPEG-4's lid middles; MediaPipe's lay up to 3% of the
    face width aside), within the eye's width of the lids found, the longest such gap is the
    opening: the upper lid point takes the vertex nearest the skin seen just above it, the lower
    one just below, of the skin vertices that face the camera (``normals``, ``MIN_FACING``),
    nearness along the view counted at ``DEPTH_WEIGHT``: the lid curls back into the socket at its
    edge, and the nearest vertex of all was one of its inner side's, 2-2.5% of the face width
    behind the edge (or one beside it, in front). Each corner keeps the column it was found in
    and takes the row of the opening's middle where the opening, followed from the middle column
    (``_opening_middles``), comes nearest that column, and the front-facing vertex nearest the
    surface seen there (or its own, where nothing is: a hole). Corners found on a vertex behind
    the lids' edge (on a lid's inner side) with the lids moved onto the edge gave one face a
    residual of 0.437, against 0.421 with neither moved and 0.396 with both; MediaPipe's corners
    3-5% low gave the other 0.414, and 0.393 moved. A corner found well inside the opening, away
    from its end, can take a vertex of the socket's wall behind it (it is seen there, facing the
    camera): on the default face with its corners put 4% of its width low, one outer corner did.
    An eye with no opening seen keeps its points."""
    axes = camera.basis() * [[1.0], [1.0], [DEPTH_WEIGHT]]
    back = axes[2] / DEPTH_WEIGHT
    front = skin[normals[skin] @ back >= MIN_FACING]
    if not len(front):
        return
    edge_tree, front_tree = cKDTree(vertices[front] @ axes.T), cKDTree(vertices[front])
    height, width = surface.shape[:2]
    for upper, lower, *corners in EYES:
        points = chosen[[upper, lower, *corners]]
        if (points < 0).any():
            continue
        pixels = project(camera, vertices[points], (width, height))
        span = int(np.linalg.norm(pixels[2] - pixels[3]))
        middle, centre = int((pixels[0, 1] + pixels[1, 1]) / 2), int((pixels[2, 0] + pixels[3, 0]) / 2)
        if not (0 <= middle < height and 0 <= centre < width):
            continue
        rows = np.arange(max(middle - span, 0), min(middle + span + 1, height))
        columns = np.arange(max(centre - span, 0), min(centre + span + 1, width))
        block = surface[rows][:, columns]
        deep = DEEP * np.linalg.norm(np.subtract(*vertices[points[2:]]))
        near = block @ back  # NaN where nothing is seen: no lid
        lid = near >= vertices[points[:2]].mean(axis=0) @ back - deep
        j = centre - columns[0]
        gaps = _gaps(lid[:, j], near[:, j], deep / 2, MIN_GAP)
        if not gaps:
            continue
        _, top, bottom = max(gaps)
        chosen[upper] = front[edge_tree.query(block[top - 1, j] @ axes.T)[1]]
        chosen[lower] = front[edge_tree.query(block[bottom, j] @ axes.T)[1]]
        for corner, x in zip(corners, pixels[2:, 0]):
            column = int(np.clip(x - columns[0], 0, len(columns) - 1))
            middles = _opening_middles(lid, near, deep / 2, j, (top, bottom), 1 if column > j else -1)
            point = block[middles[min(middles, key=lambda c: abs(c - column))], column]
            if not np.isfinite(point).all():
                point = vertices[chosen[corner]]
            chosen[corner] = front[front_tree.query(point)[1]]


def _gaps(lid: np.ndarray, near: np.ndarray, jump: float, shortest: int) -> list[tuple[int, int, int]]:
    """The runs of other pixels in a pixel column (top first) that sees lid skin where ``lid``,
    with lid skin above and below, ``shortest`` pixels long at least, seen through the lids: at
    each end, the lid pixel nearer the camera than the run's (``near``, NaN where nothing is seen)
    by ``jump`` at least (or the run's pixel sees nothing). Where the skin merely turns away from
    the camera beside an eye (a temple deeper than the lids) it crosses the lids' depth smoothly,
    and an eye's opening followed there ran into it. (length, first, after last) each."""
    change = np.flatnonzero(np.diff(lid.astype(int))) + 1
    starts, ends = change[lid[change - 1]], change[~lid[change - 1]]
    runs = [(int(end - start), int(start), int(end)) for start in starts for end in ends[ends > start][:1]]
    with np.errstate(invalid="ignore"):
        return [run for run in runs if run[0] >= shortest and not near[run[1]] > near[run[1] - 1] - jump
                and not near[run[2] - 1] > near[run[2]] - jump]


def _opening_middles(lid: np.ndarray, near: np.ndarray, jump: float, column: int, gap: tuple[int, int],
                     step: int) -> dict[int, int]:
    """{pixel column: the row of the eye opening's middle there}: the opening followed from its
    ``gap`` (rows, first and after last) in ``column`` of ``lid`` (rows, columns: where lid skin is
    seen; ``near``, ``jump``: as ``_gaps`` takes them) column by column (``step``: +1 right, -1
    left), each column's gap the longest that overlaps the one before, to the column where none does."""
    top, bottom = gap
    middles = {column: (top + bottom - 1) // 2}
    while 0 <= column + step < lid.shape[1]:
        overlapping = [run for run in _gaps(lid[:, column + step], near[:, column + step], jump, 1)
                       if run[1] < bottom and run[2] > top]
        if not overlapping:
            break
        _, top, bottom = max(overlapping)
        column += step
        middles[column] = (top + bottom - 1) // 2
    return middles


def _on_skin(vertices: np.ndarray, skin: np.ndarray, lifts: np.ndarray) -> np.ndarray:
    """(views, landmarks) bool: whether each lift lies on the skin, its nearest vertex of the whole
    mesh a skin vertex. Between parted lips a lip landmark can lift onto a tooth behind them, and
    snapped to the skin from there it took the lip's inner wall for the lip's edge (the inner lip
    loop then ran over the lips): a landmark is taken from the views that lift it onto the skin,
    where any does."""
    finite = np.isfinite(lifts).all(axis=2)
    is_skin = np.zeros(len(vertices), dtype=bool)
    is_skin[skin] = True
    out = np.zeros(finite.shape, dtype=bool)
    out[finite] = is_skin[cKDTree(vertices).query(lifts[finite])[1]]
    return out


LIP_ROWS = {"2.2": "upper", "2.6": "upper", "2.7": "upper", "2.3": "lower", "2.8": "lower", "2.9": "lower"}
"""The inner lip points and the lip they lie on. Where the lips meet (a closed mouth),
MediaPipe finds an upper and a lower point on one spot, which lifts onto the seam between the
lips: the nearest vertex can be the other lip's, or one inside the mouth (on a shape-model face
the loop through them then ran over the lips and into the mouth, 75 vertices for 38, and its
control points fell on the vermilion border's). Each is taken from its own lip's row
(``_lip_rows``); the corners, where the rows meet, from the whole skin."""


def _lip_rows(vertices: np.ndarray, normals: np.ndarray, skin: np.ndarray,
              rotation: np.ndarray) -> dict[str | None, tuple[np.ndarray, cKDTree]]:
    """{"upper" / "lower": (the skin vertices that face forward and down / up, a tree of them),
    None: (the whole skin, a tree)}: where the lips meet, the upper lip's surface faces down and
    the lower's up; inside the mouth the surface faces back. (The face frame's axes:
    ``rotation``'s rows, in the file; ``normals``: the mesh's unit vertex normals.)"""
    forward, up = normals[skin] @ rotation[2] > 0, normals[skin] @ rotation[1]
    out = {None: (skin, cKDTree(vertices[skin]))}
    for name, keep in (("upper", forward & (up < 0)), ("lower", forward & (up > 0))):
        if keep.any():
            out[name] = (skin[keep], cKDTree(vertices[skin[keep]]))
    return out


UPPER_LOWER = (("2.2", "2.3"), ("2.6", "2.8"), ("2.7", "2.9"), ("3.1", "3.3"), ("3.2", "3.4"))
"""(upper, lower) lip and lid points, which meet where a mouth or an eye is closed."""


def _row(rows: dict[str | None, tuple[np.ndarray, cKDTree]], fdp: str | None) -> tuple[np.ndarray, cKDTree]:
    """The skin vertices FDP ``fdp`` is taken from, and their tree (``LIP_ROWS``; else the skin)."""
    return rows.get(LIP_ROWS.get(fdp), rows[None])


def _apart(chosen: np.ndarray, vertices: np.ndarray, rows: dict[str | None, tuple[np.ndarray, cKDTree]],
           lifts: np.ndarray, found: np.ndarray, up: np.ndarray) -> None:
    """An upper lip (lid) point lies above its lower one, on another vertex (in place): on a closed
    mouth the inner upper and lower lip (2.2, 2.3) lift to one spot and snapped to one vertex (the
    lip loop through them pinched into a figure eight), or swapped (on a whole figure: the jaw
    opened the upper lip). Such a pair takes the two skin vertices nearest their lifts (each from
    its ``LIP_ROWS`` row) with the upper one above the lower (``up``: the face frame's +y in the file)."""
    index = {fid: i for i, fid in MEDIAPIPE_FDP.items()}
    for upper, lower in UPPER_LOWER:
        i, j = index[upper], index[lower]
        if chosen[i] < 0 or chosen[j] < 0 or vertices[chosen[i]] @ up > vertices[chosen[j]] @ up:
            continue
        targets = [np.nanmean(lifts[found, k], axis=0) for k in (i, j)]
        near = []
        for fdp, target in zip((upper, lower), targets):
            among, tree = _row(rows, fdp)
            near.append(among[tree.query(target, k=min(len(among), 12))[1]])
        cost = [np.linalg.norm(vertices[n] - t, axis=1) for n, t in zip(near, targets)]
        above = (vertices[near[0]] @ up)[:, None] > (vertices[near[1]] @ up)[None] + 1e-12 * np.ptp(vertices)
        total = np.where(above, cost[0][:, None] + cost[1][None], np.inf)
        if np.isfinite(total).any():
            a, b = np.unravel_index(np.argmin(total), total.shape)
            chosen[i], chosen[j] = near[0][a], near[1][b]


OUTER_INNER = (("8.3", "2.4"), ("8.4", "2.5"))
"""(outer, inner) lip corners: the outer corner lies beyond the inner one, away from the mid-line."""


def _outside(chosen: np.ndarray, vertices: np.ndarray, skin: tuple[np.ndarray, cKDTree], lifts: np.ndarray,
             found: np.ndarray, across: np.ndarray) -> None:
    """An outer lip corner lies beyond its inner corner, away from the mid-line (in place). On a
    face whose lips stand a little apart, MediaPipe can put the outer corner a few millimetres in
    from the inner one (3.5 mm on a shape-model face); the outer line (the vermilion border) then
    ran round the inner corner, and the lips' two contours shared vertices. Such a corner takes
    the skin vertex nearest its lifts that lies beyond the inner corner (``across``: the face
    frame's +x in the file)."""
    index = {fid: i for i, fid in MEDIAPIPE_FDP.items()}
    among, tree = skin
    inner = [chosen[index[fdp]] for _, fdp in OUTER_INNER]
    if min(inner) < 0:
        return
    middle = float(np.mean(vertices[inner] @ across))
    for outer, inner_fdp in OUTER_INNER:
        i, j = index[outer], index[inner_fdp]
        side = np.sign(vertices[chosen[j]] @ across - middle)
        if chosen[i] < 0 or side * (vertices[chosen[i]] @ across - vertices[chosen[j]] @ across) > 0:
            continue
        target = np.nanmean(lifts[found, i], axis=0)
        near = among[tree.query(target, k=min(len(among), 24))[1]]
        beyond = near[side * (vertices[near] @ across - vertices[chosen[j]] @ across) > 0]
        if len(beyond):
            chosen[i] = beyond[0]


def _distinct(chosen: np.ndarray, vertices: np.ndarray, rows: dict[str | None, tuple[np.ndarray, cKDTree]],
              lifts: np.ndarray, found: np.ndarray) -> None:
    """No two feature points on one vertex (in place): the rig puts a control point on each, and
    two in one place stop it. On a shape-model face whose upper lip stands over the lower one,
    the lower inner lip's middle and side (2.3, 2.8) snapped to one vertex. Of the points on one
    vertex, the one that would move farthest from its lifts' mean keeps it; the others take the
    nearest vertex of their row (``_row``) that no point holds."""
    target = {i: np.nanmean(lifts[found, i], axis=0) for i in found_fdps() if chosen[i] >= 0}
    held = {int(chosen[i]) for i in target}

    def elsewhere(i: int) -> int | None:
        among, tree = _row(rows, MEDIAPIPE_FDP[i])
        near = among[tree.query(target[i], k=min(len(among), 24))[1]]
        return next((int(v) for v in near if v not in held), None)

    def cost(i: int) -> float:
        other = elsewhere(i)
        return np.inf if other is None else float(np.linalg.norm(vertices[other] - target[i])
                                                  - np.linalg.norm(vertices[chosen[i]] - target[i]))

    for vertex in sorted(held):
        group = [i for i in target if chosen[i] == vertex]
        for i in sorted(group, key=cost)[:-1]:
            other = elsewhere(i)
            if other is not None:
                chosen[i] = other
                held.add(other)


def skin_vertices(vertices: np.ndarray, triangles: np.ndarray, lifts: np.ndarray) -> np.ndarray:
    """The vertices of the connected component most lifted landmarks lie nearest (the skin)."""
    component = components(len(vertices), triangles)
    points = lifts.reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1)]
    hits = component[cKDTree(vertices).query(points)[1]]
    return np.flatnonzero(component == np.bincount(hits).argmax())


class Shots:
    """Renders of one mesh with, beside each, its surface points per pixel; a context of its own."""

    def __init__(self, face: Face, size: int) -> None:
        self.face, self.size = face, size
        self.vertices = np.asarray(face.vertices, float)
        self.centre = (self.vertices.min(axis=0) + self.vertices.max(axis=0)) / 2
        self.normals = VertexNormals(np.asarray(face.triangles), len(self.vertices))(self.vertices)
        self.ctx = moderngl.create_context(standalone=True, backend="egl")
        try:
            with self.ctx:
                self.renderer = Renderer.for_face(face, detail=False, ctx=self.ctx, width=size, height=size,
                                                  cull=False)
                self.surface = SurfacePass(self.ctx, self.vertices - self.centre, face.triangles, (size, size))
        except BaseException:
            self.ctx.release()
            raise

    def __enter__(self) -> Shots:
        return self

    def __exit__(self, *exc_info: object) -> None:
        with self.ctx:
            self.renderer.release()
            self.surface.release()
        self.ctx.release()

    def framing(self, rotation: np.ndarray, points: np.ndarray, share: float, yaw: float = 0.0,
                pitch: float = 0.0) -> Camera:
        """A camera in the face frame ``rotation`` (file -> face) turned by yaw and pitch (degrees),
        aimed at the box of ``points`` (file coordinates) so that it spans ``share`` of the image."""
        local = (np.asarray(points, float) - self.centre) @ rotation.T
        middle = (local.min(axis=0) + local.max(axis=0)) / 2
        extent = np.ptp(local, axis=0)
        a, b = np.radians(yaw), np.radians(pitch)
        direction = np.array([np.sin(a) * np.cos(b), np.sin(b), np.cos(a) * np.cos(b)])
        distance = max(extent[0], extent[1]) / share / (2 * np.tan(np.radians(FOV) / 2)) + extent[2] / 2
        target = self.centre + rotation.T @ middle
        reach = np.linalg.norm(np.ptp(self.vertices, axis=0))
        return Camera(eye=target + rotation.T @ (distance * direction), target=target, up=rotation.T @ [0.0, 1.0, 0.0],
                      fov=FOV, near=max(distance - reach, distance / 100), far=distance + reach)

    def skin_surface(self, camera: Camera, skin: np.ndarray) -> np.ndarray:
        """The surface points (H, W, 3) of the skin alone (the triangles whose corners are all
        ``skin`` vertices) seen by ``camera``, NaN where none is: through an eye opening, what lies
        behind the eyeball (``_lid_edges``)."""
        triangles = np.asarray(self.face.triangles)
        alone = triangles[np.isin(triangles, skin).all(axis=1)]
        shifted = replace(camera, eye=camera.eye - self.centre, target=camera.target - self.centre)
        with self.ctx:
            skin_pass = SurfacePass(self.ctx, self.vertices - self.centre, alone, (self.size, self.size))
            try:
                return skin_pass.points(shifted) + self.centre
            finally:
                skin_pass.release()

    def shoot(self, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """(the render (H, W, 3) uint8, the surface point per pixel (H, W, 3) file coordinates, NaN
        where no surface is)."""
        self.renderer.camera = camera
        with self.ctx:
            image = self.renderer.render(self.vertices.astype(np.float32))
            shifted = replace(camera, eye=camera.eye - self.centre, target=camera.target - self.centre)
            surface = self.surface.points(shifted) + self.centre
        return image, surface

    def detect(self, cameras: list[Camera], folder: Path, stem: str,
               name: str) -> tuple[list[bool], list[tuple[np.ndarray, np.ndarray]]]:
        """Render each camera's view, find landmarks on all in one run, lift them: (whether a face
        was found per view, per view (points (478, 3), facing (478,)), NaN / 0 where unseen)."""
        shots, paths = [], []
        for k, camera in enumerate(cameras):
            image, surface = self.shoot(camera)
            paths.append(folder / f"{stem}{k:02d}.bmp")  # uncompressed: encoding 14 PNGs took 1.1 s of 4.6
            Image.fromarray(image).save(paths[-1])
            shots.append((camera, surface))
        results = detect_faces(paths, name)
        lifts = [self._lift(camera, surface, result["points"]) for (camera, surface), result in zip(shots, results)]
        return [result["faces"] >= 1 for result in results], lifts

    def _lift(self, camera: Camera, surface: np.ndarray, pixels: list) -> tuple[np.ndarray, np.ndarray]:
        """Landmark pixels -> (surface points (478, 3), cos of the angle between the surface there
        and the view (478,)); NaN and 0 where a landmark falls off the mesh or none was found."""
        points, facing = np.full((478, 3), np.nan), np.zeros(478)
        if not pixels:
            return points, facing
        xy = np.asarray(pixels, float)[:, :2]
        col = np.clip(xy[:, 0].astype(int), 0, self.size - 1)
        row = np.clip(xy[:, 1].astype(int), 0, self.size - 1)
        points = surface[row, col]
        hit = np.isfinite(points).all(axis=1)
        nearest = cKDTree(self.vertices).query(points[hit])[1]
        view = camera.eye - points[hit]
        view /= np.linalg.norm(view, axis=1, keepdims=True)
        facing[hit] = np.abs(np.einsum("ij,ij->i", self.normals[nearest], view))
        return points, facing


class SurfacePass:
    """An offscreen pass that writes, per pixel, the position of the mesh surface seen there
    (float32, relative to the positions uploaded), both faces drawn, depth tested."""

    _VERTEX = """#version 330
    uniform mat4 view_projection;
    in vec3 in_position;
    out vec3 position;
    void main() { position = in_position; gl_Position = view_projection * vec4(in_position, 1.0); }"""
    _FRAGMENT = """#version 330
    in vec3 position;
    out vec4 surface;
    void main() { surface = vec4(position, 1.0); }"""

    def __init__(self, ctx: moderngl.Context, vertices: np.ndarray, triangles: np.ndarray,
                 size: tuple[int, int]) -> None:
        self.ctx, self.size = ctx, size
        self.program = ctx.program(vertex_shader=self._VERTEX, fragment_shader=self._FRAGMENT)
        self.buffers = [ctx.buffer(np.ascontiguousarray(vertices, dtype="f4")),
                        ctx.buffer(np.ascontiguousarray(triangles, dtype="u4"))]
        self.array = ctx.vertex_array(self.program, [(self.buffers[0], "3f", "in_position")],
                                      index_buffer=self.buffers[1], index_element_size=4)
        self.targets = [ctx.renderbuffer(size, components=4, dtype="f4"), ctx.depth_renderbuffer(size)]
        self.framebuffer = ctx.framebuffer(color_attachments=[self.targets[0]], depth_attachment=self.targets[1])

    def points(self, camera: Camera) -> np.ndarray:
        """(H, W, 3) surface points seen by ``camera`` (uploaded coordinates: the caller adds back
        what it took off), top row first; NaN where no surface is. The context must be current."""
        aspect = self.size[0] / self.size[1]
        self.program["view_projection"].write(
            np.ascontiguousarray((camera.projection_matrix(aspect) @ camera.view_matrix()).T, dtype="f4"))
        self.framebuffer.use()
        self.framebuffer.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        self.array.render(moderngl.TRIANGLES)
        data = np.frombuffer(self.framebuffer.read(components=4, dtype="f4"), dtype=np.float32)
        grid = data.reshape(self.size[1], self.size[0], 4)[::-1].astype(float)
        grid[grid[..., 3] < 0.5] = np.nan
        return grid[..., :3]

    def release(self) -> None:
        for obj in (self.array, self.program, self.framebuffer, *self.targets, *self.buffers):
            obj.release()
