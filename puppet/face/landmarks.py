"""Landmarks to a rig-ready face: what a new mesh needs before ``puppet.face.autorig`` can rig it.

A new face comes as a mesh plus landmarks, either a JSON object mapping MPEG-4 FDP ids to vertex
indices (``{"2.1": 152, ...}``) or a JSON list of 68 vertex indices in the iBUG 68-point order.
:func:`apply_landmarks` turns that into everything ``build_rig`` reads:

* **Face frame.** The given feature points are fitted to the default face's (Procrustes), and the
  mesh is turned into the MPEG-4 face frame (+x the face's left, +y up, +z forward) with its
  mid-line at x = 0; units stay as in the file. ``Face.placement`` keeps the [R | t] that did it.
  Coordinates are then rounded to a power-of-two grid 1e-9 of the face's size, so a point that
  sits exactly on the mid-line (or level with a feature point) stays there whatever rotation
  the file had: the rig of a rotated, scaled copy is the same rig.
* **Parts.** Connected components: the one holding the landmarks is ``skin``; near each eye
  opening, a component about as large as the eye is that eyeball (``eye_l`` / ``eye_r``); inside
  the mouth, small ones are teeth and flat arches gums (``teeth_upper`` / ``teeth_lower``: each
  tooth goes with the gum nearest it, else by the lip line), one longer than wide under the lips
  is the ``tongue``, and other large ones the ``mouth`` (a socket); anything else (lashes, tear lines) is ``attached``: it follows the skin
  region nearest to it. A face without eyeballs or teeth simply has none of those regions.
  Parts the file's own pieces named (``puppet.face.meshparts``: eyeballs, teeth, tongue,
  lashes) win over the components' guess off the skin; eyeballs are sided by x in the face frame.
  Vertices at the very same place in the same part are joined (``_seams``): a glTF exporter
  splits vertices along uv seams, and the skin would else come in islands.
* **Contours.** The lips' meeting line, the vermilion border and the lid openings, as closed
  loops of shortest (geodesic) paths on the skin through their landmarks; the face oval the same
  way through the chin's sides, the jaw and hairline points (``FACE_OVAL``, placed below), as
  the default face's runs: without it the rig has no jaw band, and an opening jaw folds the skin
  under it. The skin's open boundary below the chin, where there is one, is the ``neck_cut``.
  Open holes and closed (stitched) mouths and eyes are handled alike.
* **Feature points.** iBUG points map directly where MPEG-4 has the same point (eye and lip
  corners, brows, nose tip and base, lip mid points, chin); lid and lower-lip mid points are the
  halfway vertex of the geodesic path between their two iBUG neighbours. Every other FDP
  (cheeks, jaw angles, nose bone, hairline, ears, ...) is placed the adaptive way (Zhou & Liu):
  written in the frame of its three nearest given feature points on the default face
  (``muscles.place_coefficients``), placed by the same coefficients on the new face, and snapped
  to the nearest skin vertex inside its block: the face's feature-point box is cut into an
  ``GRID`` x ``GRID`` grid and the search keeps to the block around the point and its neighbours,
  and to vertices within a geodesic reach of the nearest given point (so a point never snaps
  across a lip or a lid). Pupils are the front of the eyeball, or placed the same way when the
  face has none; eyeball centres are the eyeball's box centre, or placed. Teeth and tongue
  points are left out (their regions are empty on a face without them).
"""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from puppet.errors import PuppetError
from puppet.face.default import default_face
from puppet.face.meshparts import components
from puppet.face.muscles import place, place_coefficients

__all__ = ["LandmarkError", "apply_landmarks", "ibug_to_fdp", "read_landmarks"]

GROUP_SIZES = {2: 14, 3: 14, 4: 6, 5: 4, 6: 4, 7: 1, 8: 10, 9: 15, 10: 10, 11: 6}
GRID = 8  # the M x N blocks the face's feature-point box is cut into for the snapping search
LEG_REACH = 4.0  # how far, in straight distances between its ends, a contour's leg is sought first
SKIPPED = {"6.1", "6.2", "6.3", "6.4", "9.8", "9.9", "9.10", "9.11"}  # teeth and tongue points

# iBUG 68 (0-based; "left" is the face's own left, +x) -> the FDP at the same place.
IBUG_FDP = {
    "2.1": 8, "4.1": 22, "4.2": 21, "4.3": 24, "4.4": 19, "4.5": 26, "4.6": 17,
    "3.7": 45, "3.11": 42, "3.8": 39, "3.12": 36, "9.3": 30, "9.15": 33,
    "8.4": 48, "8.6": 49, "8.9": 50, "8.1": 51, "8.10": 52, "8.5": 53, "8.3": 54, "8.2": 57,
    "2.5": 60, "2.7": 61, "2.2": 62, "2.6": 63, "2.4": 64, "2.8": 65, "2.3": 66, "2.9": 67,
}
# FDPs halfway along the geodesic path through these iBUG points.
IBUG_MIDWAY = {"3.1": (43, 44), "3.3": (47, 46), "3.2": (38, 37), "3.4": (40, 41),
               "8.7": (54, 55, 56, 57), "8.8": (48, 59, 58, 57)}
IBUG_CONTOURS = {"mouth_opening": list(range(60, 68)), "vermilion_border": list(range(48, 60)),
                 "left_lid_opening": list(range(42, 48)), "right_lid_opening": list(range(36, 42))}
# The same loops through FDPs, for a face given by FDP ids; these points must be given.
FDP_CONTOURS = {
    "mouth_opening": ["2.5", "2.7", "2.2", "2.6", "2.4", "2.8", "2.3", "2.9"],
    "vermilion_border": ["8.4", "8.6", "8.9", "8.1", "8.10", "8.5", "8.3", "8.7", "8.2", "8.8"],
    "left_lid_opening": ["3.7", "3.1", "3.11", "3.3"],
    "right_lid_opening": ["3.12", "3.2", "3.8", "3.4"],
}
# The default face's oval passes these (in front of 2.1, which sits under the chin).
FACE_OVAL = ["2.11", "2.13", "11.3", "11.1", "11.2", "2.14", "2.12"]
FDP_NEEDED = sorted({f for loop in FDP_CONTOURS.values() for f in loop} | {"2.1", "9.3", "9.15"})
# What each needed point is (MPEG-4 Annex C; "left" is the face's own left, on a photo's right).
FDP_NEEDED_WHAT = {
    "2.1": "bottom of the chin", "9.3": "nose tip", "9.15": "base of the nose, above the upper lip",
    "2.2": "inner lip line, top, middle", "2.3": "inner lip line, bottom, middle",
    "2.4": "inner lip line, left corner", "2.5": "inner lip line, right corner",
    "2.6": "inner lip line, top, halfway to the left corner", "2.7": "inner lip line, top, halfway to the right corner",
    "2.8": "inner lip line, bottom, halfway to the left corner",
    "2.9": "inner lip line, bottom, halfway to the right corner",
    "8.1": "upper lip's outer edge, middle", "8.2": "lower lip's outer edge, middle",
    "8.3": "left mouth corner (outer)", "8.4": "right mouth corner (outer)",
    "8.5": "upper lip's outer edge, between the left peak and corner",
    "8.6": "upper lip's outer edge, between the right peak and corner",
    "8.7": "lower lip's outer edge, halfway to the left corner",
    "8.8": "lower lip's outer edge, halfway to the right corner",
    "8.9": "upper lip's right peak (Cupid's bow)", "8.10": "upper lip's left peak (Cupid's bow)",
    "3.1": "left upper lid, middle of its edge", "3.2": "right upper lid, middle of its edge",
    "3.3": "left lower lid, middle of its edge", "3.4": "right lower lid, middle of its edge",
    "3.7": "left eye, outer corner", "3.8": "right eye, inner corner",
    "3.11": "left eye, inner corner", "3.12": "right eye, outer corner",
}
KEPT_PARTS = {"eye_l", "eye_r", "teeth_upper", "teeth_lower", "tongue", "attached"}  # a file's named pieces
PUPILS = ("3.5", "3.6")  # coordinates when the face has no eyeball to put them on
EYES = {"eye_l": ("3.7", "3.11", "3.5"), "eye_r": ("3.12", "3.8", "3.6")}


class LandmarkError(PuppetError, ValueError):
    """Landmarks that cannot be used; the message names the source and the problem."""


class Skin(NamedTuple):
    """The skin's edge graph (weighted by edge length), the positions and the skin mask."""

    graph: sp.csr_matrix
    positions: np.ndarray
    mask: np.ndarray


# -- reading -------------------------------------------------------------------------------------

def read_landmarks(source, n_vertices: int) -> dict[str, int] | list[int]:
    """Landmarks from a JSON file path, a dict {FDP id: vertex} or a list of 68 vertices, checked
    against a mesh of ``n_vertices`` vertices."""
    name = "landmarks"
    if isinstance(source, (str, os.PathLike)):
        name = str(source)
        try:
            source = json.loads(Path(source).read_text())
        except OSError as exc:
            raise LandmarkError(f"{name}: cannot read landmarks ({exc.strerror or exc})") from None
        except json.JSONDecodeError as exc:
            raise LandmarkError(f"{name}:{exc.lineno}: not valid JSON ({exc.msg})") from None
    if isinstance(source, dict):
        held = _ibug_key(source, name)
        if held is not None:
            source = source[held]
        else:
            return {fid: _index(v, n_vertices, f"{name}: FDP {fid}") for fid, v in _fdp_items(source, name)}
    if isinstance(source, (list, tuple)):
        if len(source) != 68:
            raise LandmarkError(f"{name}: a landmark list must hold the 68 iBUG points, got {len(source)}")
        return [_index(v, n_vertices, f"{name}: iBUG point {i}") for i, v in enumerate(source)]
    raise LandmarkError(f"{name}: expected an object of FDP ids or a list of 68 vertex indices, "
                        f"got {type(source).__name__}")


def _ibug_key(data: dict, name: str) -> str | None:
    """The key of an object with no FDP ids that holds the 68 iBUG vertex indices as one list (as
    ICT-FaceKit's ``vertex_indices.json`` does under ``idx_to_landmark_verts``); None for an object
    of FDP ids. Several such lists are a LandmarkError naming them."""
    if any(is_fdp(key) for key in data):
        return None
    lists = [key for key, value in data.items() if isinstance(value, list) and len(value) == 68
             and all(isinstance(v, int) and not isinstance(v, bool) for v in value)]
    if len(lists) > 1:
        raise LandmarkError(f"{name}: several keys hold 68 vertex indices ({', '.join(map(repr, lists))}): "
                            "give a file with the iBUG 68 list alone, or an object of FDP ids")
    return lists[0] if lists else None


def _fdp_items(data: dict, name: str) -> list[tuple[str, object]]:
    bad = [k for k in data if not is_fdp(k)]
    if bad:
        raise LandmarkError(f"{name}: unknown FDP id(s) {_clip_list(bad)} (MPEG-4 ids look like '2.1' .. '11.6'; "
                            "or give the 68 iBUG vertex indices, as a list or under one key)")
    return list(data.items())


def _clip_list(items: list, most: int = 5) -> str:
    shown = ", ".join(map(repr, items[:most]))
    return f"[{shown}{f', ... ({len(items)} in all)' if len(items) > most else ''}]"


def is_fdp(key: str) -> bool:
    """Whether ``key`` names an MPEG-4 feature point ('2.1' .. '11.6')."""
    group, _, index = str(key).partition(".")
    return group.isdigit() and index.isdigit() and 1 <= int(index) <= GROUP_SIZES.get(int(group), 0)


def _index(value, n_vertices: int, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise LandmarkError(f"{where}: vertex index must be an integer, got {value!r}")
    if not 0 <= value < n_vertices:
        raise LandmarkError(f"{where}: vertex index {value} outside 0..{n_vertices - 1}")
    return int(value)


# -- iBUG 68 -> FDP ----------------------------------------------------------------------------------

def ibug_to_fdp(ibug: list[int], skin: Skin) -> tuple[dict[str, int], dict[str, list[int]]]:
    """The FDPs the 68 iBUG vertices give (direct and halfway points) and the contour waypoints."""
    fdp = {fid: ibug[i] for fid, i in IBUG_FDP.items()}
    for fid, chain in IBUG_MIDWAY.items():
        fdp[fid] = _halfway(skin, [ibug[i] for i in chain])
    contours = {name: [ibug[i] for i in chain] for name, chain in IBUG_CONTOURS.items()}
    return fdp, contours


def _halfway(skin: Skin, waypoints: list[int]) -> int:
    """The vertex halfway (by length) along the geodesic path through the waypoints."""
    path = _geodesic_path(skin, waypoints, closed=False)
    steps = np.linalg.norm(np.diff(skin.positions[path], axis=0), axis=1) if len(path) > 1 else np.zeros(0)
    run = np.concatenate([[0.0], np.cumsum(steps)])
    return int(path[np.argmin(np.abs(run - run[-1] / 2))])


def _check_needed(landmarks: dict[str, int], name: str) -> None:
    """A LandmarkError naming each needed feature point (``FDP_NEEDED``) missing from ``landmarks``
    and what it is: the others are placed from these, and the lip and lid loops run through them."""
    missing = [f for f in FDP_NEEDED if f not in landmarks]
    if missing:
        listed = "; ".join(f"{f} ({FDP_NEEDED_WHAT[f]})" for f in missing)
        raise LandmarkError(f"{name}: {_plural(len(missing), 'needed feature point')} missing: {listed}; "
                            f"rig needs these {len(FDP_NEEDED)} (the lip and lid loops, chin, nose tip and base)")


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


# -- the face -------------------------------------------------------------------------------------

def apply_landmarks(face, landmarks) -> object:
    """A copy of ``face`` in the face frame with parts, contours, pivots and all feature points
    (module docstring), ready for ``autorig.build_rig``."""
    source, landmarks = landmarks, read_landmarks(landmarks, len(face.vertices))
    seams = _seams(face.vertices, _pieces(face))
    skin = _skin_graph(face.vertices, face.triangles, _landmark_component(face, landmarks, seams), seams)
    if isinstance(landmarks, list):
        given, waypoints = ibug_to_fdp(landmarks, skin)
    else:
        _check_needed(landmarks, str(source) if isinstance(source, (str, os.PathLike)) else "landmarks")
        given = dict(landmarks)
        waypoints = {name: [given[f] for f in loop] for name, loop in FDP_CONTOURS.items()}
    reference = default_face()
    placement = _placement(face.vertices, given, reference.feature_points)
    vertices = _snapped(face.vertices @ placement[:, :3].T + placement[:, 3], face.vertices, given)
    skin = _skin_graph(vertices, face.triangles, skin.mask, seams)
    parts = _parts(vertices, face.triangles, skin.mask, {f: vertices[i] for f, i in given.items()}, face.parts,
                   seams)
    contours = _lip_contours(skin, waypoints)
    feature_points, feature_vertices = _feature_points(vertices, parts, skin, given, reference)
    contours["face_oval"] = _geodesic_path(skin, [feature_vertices[f] for f in FACE_OVAL], closed=True)
    neck = _neck_cut(vertices, face.triangles, skin.mask, seams, feature_points["2.1"][1])
    if neck is not None:
        contours["neck_cut"] = neck
    return replace(face, vertices=vertices, parts=parts, feature_points=feature_points,
                   feature_vertices=feature_vertices, contours=contours, placement=placement,
                   pivots=_pivots(vertices, parts, feature_points, reference))


def _neck_cut(vertices: np.ndarray, triangles: np.ndarray, on_skin: np.ndarray, seams: np.ndarray,
              chin_y: float) -> np.ndarray | None:
    """The skin's open boundary below the chin, as a loop (the default face's ``neck_cut``): where a
    head is cut off at the neck, the band from it up to the chin carries the head's turn into the
    still bust. None when no boundary loop lies wholly below the chin (a mask, a closed head)."""
    twin = np.arange(len(vertices))
    twin[seams[:, 0]] = seams[:, 1]
    tri = twin[np.asarray(triangles)[on_skin[np.asarray(triangles)].all(axis=1)]]
    pairs = np.sort(np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    n = len(vertices)
    keys, count = np.unique(pairs[:, 0].astype(np.int64) * n + pairs[:, 1], return_counts=True)
    rim = np.stack([keys[count == 1] // n, keys[count == 1] % n], axis=1)
    if not len(rim):
        return None
    graph = sp.coo_matrix((np.ones(len(rim)), (rim[:, 0], rim[:, 1])), shape=(n, n)).tocsr()
    graph = graph + graph.T
    comp = connected_components(graph, directed=False)[1]
    degree = np.diff(graph.indptr)
    loops = [c for c in np.unique(comp[rim[:, 0]]) if (degree[comp == c] == 2).all()
             and vertices[comp == c, 1].max() < chin_y]
    if not loops:
        return None
    members = max(loops, key=lambda c: (np.count_nonzero(comp == c), -c))
    return _walk(graph, int(np.flatnonzero(comp == members)[0]))


def _walk(graph: sp.csr_matrix, start: int) -> np.ndarray:
    """The vertices of the cycle through ``start`` (every vertex on it of degree 2), in order."""
    path, previous, v = [start], -1, start
    while True:
        nxt = [int(w) for w in graph.indices[graph.indptr[v]:graph.indptr[v + 1]] if w != previous]
        previous, v = v, nxt[0]
        if v == start:
            return np.array(path, dtype=np.int32)
        path.append(v)


def _landmark_component(face, landmarks, seams: np.ndarray) -> np.ndarray:
    """Per vertex, whether it lies in the connected component holding most landmarks (the skin)."""
    comp = components(len(face.vertices), face.triangles, seams)
    marks = list(landmarks.values()) if isinstance(landmarks, dict) else landmarks
    return comp == np.bincount(comp[marks]).argmax()


def seam_pairs(face) -> np.ndarray:
    """(k, 2) pairs (vertex, its twin): the vertices an exporter split along a uv seam (one place,
    one part), to be joined wherever connectivity matters."""
    return _seams(face.vertices, _pieces(face))


def _seams(vertices: np.ndarray, piece: np.ndarray) -> np.ndarray:
    """(k, 2) pairs (vertex, the first vertex at the same place in the same piece of the file)."""
    keyed = np.c_[np.asarray(vertices, dtype=float), piece]
    _, first, inverse = np.unique(keyed, axis=0, return_index=True, return_inverse=True)
    twin = first[inverse.ravel()]
    split = np.flatnonzero(twin != np.arange(len(vertices)))
    return np.c_[split, twin[split]]


def _pieces(face) -> np.ndarray:
    """Per vertex, the number of the part the file's pieces put it in (seams join within one)."""
    out = np.zeros(len(face.vertices))
    for k, members in enumerate(face.parts.values()):
        out[members] = k
    return out


def _edges(triangles: np.ndarray) -> np.ndarray:
    """The mesh's edges (a, b), a < b, each once, sorted (one int64 key per edge: ``np.unique``
    on rows sorts a structured view, ten times slower)."""
    t = np.asarray(triangles, dtype=np.int64)
    pairs = np.sort(np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    n = int(t.max(initial=0)) + 1
    keys = np.unique(pairs[:, 0] * n + pairs[:, 1])
    return np.stack([keys // n, keys % n], axis=1)


def _skin_graph(vertices: np.ndarray, triangles: np.ndarray, on_skin: np.ndarray, seams: np.ndarray) -> Skin:
    """The skin's edge graph, weighted by edge length, its ``seams`` joined."""
    e = np.vstack([_edges(triangles), seams])
    e = e[on_skin[e].all(axis=1)]
    n = len(vertices)
    length = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1) + 1e-300
    graph = sp.coo_matrix((length, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    return Skin(graph, np.asarray(vertices, float), on_skin)


def _lip_contours(skin: Skin, waypoints: dict[str, list[int]]) -> dict[str, np.ndarray]:
    """The contours through their waypoints (``_geodesic_path``), each keeping off those made
    before it (the lips' inner line first, then the outer one round it): on a face whose found
    outer mouth corners lay a vertex or two from the inner ones, the outer line's shortest way
    ran through the inner corner, and the lips' two edges shared vertices."""
    made: dict[str, np.ndarray] = {}
    for name, ways in waypoints.items():
        kept_off = np.zeros(skin.graph.shape[0], dtype=bool)
        for contour in made.values():
            kept_off[contour] = True
        made[name] = _geodesic_path(skin, ways, closed=True, kept_off=kept_off)
    return made


def _geodesic_path(skin: Skin, waypoints: list[int], closed: bool, kept_off: np.ndarray | None = None) -> np.ndarray:
    """Vertices along shortest skin paths from waypoint to waypoint (back to the first if closed).
    Each leg keeps off the vertices the legs before it took, so a loop never touches itself: two
    waypoints near one corner (found landmarks a vertex or two apart) sent two shortest legs
    through one vertex, which became both an upper and a lower lid point, two control points on
    one place (``duplicate sites``); and off ``kept_off`` (another contour's vertices). A leg with
    no way round them takes the plain shortest path."""
    stops = list(waypoints) + ([waypoints[0]] if closed else [])
    path: list[int] = [stops[0]]
    for a, b in zip(stops[:-1], stops[1:]):
        taken = np.zeros(skin.graph.shape[0], dtype=bool) if kept_off is None else kept_off.copy()
        taken[path] = True
        taken[[a, b]] = False
        path += _leg(skin, a, b, taken) or _leg(skin, a, b, np.zeros_like(taken))
    if closed:
        path = path[:-1]
    return np.array(path, dtype=np.int32)


def _leg(skin: Skin, a: int, b: int, blocked: np.ndarray) -> list[int]:
    """The shortest path's vertices after ``a`` up to ``b`` avoiding the ``blocked`` vertices;
    [] when there is none (a == b gives []). The path is sought within ``LEG_REACH`` times the
    straight distance from ``a`` first, then over the whole skin: the same path, found near."""
    graph = skin.graph
    if blocked.any():
        rows = np.repeat(np.arange(graph.shape[0]), np.diff(graph.indptr))
        graph = graph.copy()
        graph.data[blocked[rows] | blocked[graph.indices]] = 0.0
        graph.eliminate_zeros()
    reach = LEG_REACH * np.linalg.norm(skin.positions[a] - skin.positions[b])
    for limit in (reach, np.inf):
        _, pred = dijkstra(graph, directed=False, indices=a, return_predecessors=True, limit=limit)
        if a == b or pred[b] >= 0:
            break
    leg, v = [], b
    while v != a:
        if v < 0:
            if blocked.any():
                return []
            raise LandmarkError(f"landmarks: vertices {a} and {b} are not connected on the skin")
        leg.append(int(v))
        v = pred[v]
    return leg[::-1]


def _placement(vertices: np.ndarray, given: dict[str, int], reference: dict[str, np.ndarray]) -> np.ndarray:
    """[R | t]: the rotation that best fits the given points to the default face's (Procrustes),
    then a shift along x that puts the fitted mid-line at x = 0."""
    ids = sorted(given)
    p = vertices[[given[f] for f in ids]]
    q = np.array([reference[f] for f in ids])
    pc, qc = p - p.mean(axis=0), q - q.mean(axis=0)
    u, s, vt = np.linalg.svd(qc.T @ pc)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    R = u @ d @ vt
    scale = np.sqrt((pc ** 2).sum() / (qc ** 2).sum())
    shift = (R @ p.mean(axis=0))[0] - scale * q.mean(axis=0)[0]
    return np.hstack([R, np.array([[-shift], [0.0], [0.0]])])


def _snapped(vertices: np.ndarray, original: np.ndarray, given: dict[str, int]) -> np.ndarray:
    """Coordinates rounded to a power-of-two grid 1e-9 of the landmarks' extent (module docstring)."""
    extent = np.linalg.norm(np.ptp(original[list(given.values())], axis=0))
    q = 2.0 ** np.round(np.log2(1e-9 * extent))
    return np.round(vertices / q) * q


# -- parts -------------------------------------------------------------------------------------------

def _parts(vertices: np.ndarray, triangles: np.ndarray, on_skin: np.ndarray,
           fp: dict[str, np.ndarray], loaded: dict[str, np.ndarray], seams: np.ndarray) -> dict[str, np.ndarray]:
    """Split the mesh's components into skin, eyeballs, teeth, mouth and attached (module docstring);
    off the skin, the parts the file's pieces named (``loaded``) are kept, eyeballs sided anew."""
    comp = components(len(vertices), triangles, seams)
    label = np.full(len(vertices), "skin", dtype=object)
    for c in np.unique(comp[~on_skin]):
        members = comp == c
        label[members] = _part_of(vertices[members], fp)
    _side_teeth(vertices, comp, label)
    for name in KEPT_PARTS & set(loaded):
        kept = np.asarray(loaded[name])[~on_skin[loaded[name]]]
        label[kept] = name
    eyes = np.isin(label, ["eye_l", "eye_r"]) & ~on_skin
    label[eyes] = np.where(vertices[eyes, 0] >= 0, "eye_l", "eye_r")
    return {name: np.flatnonzero(label == name).astype(np.int32) for name in sorted(set(label))}


def _part_of(p: np.ndarray, fp: dict[str, np.ndarray]) -> str:
    centre, size = p.mean(axis=0), np.ptp(p, axis=0)
    for part, (outer, inner, _) in EYES.items():
        width = np.linalg.norm(fp[outer] - fp[inner])
        if np.linalg.norm(centre - (fp[outer] + fp[inner]) / 2) < width and size.min() > 0.6 * width:
            return part
    mouth_w = abs(fp["8.3"][0] - fp["8.4"][0])
    lip_y = (fp["2.2"][1] + fp["2.3"][1]) / 2
    if abs(centre[0]) < mouth_w and fp["2.1"][1] < centre[1] < fp["9.15"][1] and centre[2] < fp["2.2"][2]:
        if size.max() < 0.75 * mouth_w or size[1] < 0.5 * size[0]:  # a tooth, or a gum: a flat arch
            return "teeth_upper" if centre[1] >= lip_y else "teeth_lower"
        if size[2] > size[0] and centre[1] < lip_y:  # longer than wide, under the lips
            return "tongue"
        return "mouth"
    return "attached"


def _side_teeth(vertices: np.ndarray, comp: np.ndarray, label: np.ndarray) -> None:
    """Each tooth goes with the gum nearest to it: the back teeth of a lower arch rise above the
    lips' line, which alone put them in the upper teeth. Without both gums, the line stands."""
    teeth = np.isin(label, ["teeth_upper", "teeth_lower"])
    sizes = np.bincount(comp[teeth], minlength=comp.max() + 1)
    gums = {side: c for side in ("teeth_upper", "teeth_lower")
            for c in [max(np.unique(comp[label == side]), key=lambda k: sizes[k], default=-1)]}
    if min(gums.values()) < 0 or min(sizes[list(gums.values())]) < 2 * np.median(sizes[sizes > 0]):
        return
    trees = {side: cKDTree(vertices[comp == c]) for side, c in gums.items()}
    for c in np.unique(comp[teeth]):
        if c in gums.values():
            continue
        centre = vertices[comp == c].mean(axis=0)
        label[comp == c] = min(gums, key=lambda side: trees[side].query(centre)[0])


# -- feature points and pivots ---------------------------------------------------------------------

def _feature_points(vertices: np.ndarray, parts: dict[str, np.ndarray], skin: Skin,
                    given: dict[str, int], reference) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """All FDPs but teeth and tongue: the given ones, pupils, and the rest placed adaptively."""
    fv = dict(given)
    fp = {f: vertices[i].copy() for f, i in given.items()}
    for part, (_, _, pupil) in EYES.items():
        if part in parts and pupil not in fp:
            eye = vertices[parts[part]]
            fp[pupil] = eye[np.argmax(eye[:, 2])].copy()
    blocks = _Blocks(np.array(list(fp.values())))
    for fid in sorted(set(reference.feature_points) - set(fp) - SKIPPED):
        ids = _frame_ids(reference.feature_points, fid, sorted(given), fp)
        target = _placed(fp, reference.feature_points[fid], reference.feature_points, ids)
        if fid in reference.feature_vertices and fid not in PUPILS:
            fv[fid] = _snap(vertices, skin, blocks, target, [given[i] for i in ids], np.array(list(fv.values())))
            fp[fid] = vertices[fv[fid]].copy()
        else:
            fp[fid] = target
    return fp, fv


def _placed(fp: dict[str, np.ndarray], point: np.ndarray, reference: dict[str, np.ndarray],
            ids: list[str]) -> np.ndarray:
    """``point`` of the default face carried to this face through the frame of ``ids``; a point
    on the default face's mid-line stays on the mid-line."""
    target = place(fp, ids, place_coefficients(point, reference, ids))
    if abs(point[0]) < 1e-9:
        target[0] = 0.0
    return target


PROPER = np.radians(15)
"""The smallest angle of a proper frame triangle (``_frame_ids``)."""


def _frame_ids(reference: dict[str, np.ndarray], fid: str, known: list[str],
               here: dict[str, np.ndarray]) -> list[str]:
    """The three given feature points nearest ``fid`` on the default face that make a proper
    triangle there (no angle under ``PROPER``) and not a sliver on this face (``here``: no angle
    under half of it): the frame its position is written in. (Proper on the default face alone,
    the chin's 2.1 and 2.10 and a lip point, found nearly in line on a face of another shape
    (6.6 degrees), turned the frame's sideways axis at random: 2.11 and 2.12 both landed on the
    chin's mid-line, one vertex. Proper on both, ICT's ears and jaw angles, framed at 15.0
    degrees on ICT, were framed by points farther away and placed inside the head.)"""
    order = sorted(known, key=lambda k: (np.linalg.norm(reference[k] - reference[fid]), k))
    for k in range(3, len(order) + 1):
        for a in range(k - 2):
            for b in range(a + 1, k - 1):
                ids = [order[a], order[b], order[k - 1]]
                if (_min_angle(np.array([reference[i] for i in ids])) > PROPER
                        and _min_angle(np.array([here[i] for i in ids])) > PROPER / 2):
                    return ids
    raise LandmarkError(f"landmarks: no three given feature points frame FDP {fid}")


def _min_angle(tri: np.ndarray) -> float:
    angles = []
    for i in range(3):
        u, w = tri[(i + 1) % 3] - tri[i], tri[(i + 2) % 3] - tri[i]
        angles.append(np.arccos(np.clip(u @ w / (np.linalg.norm(u) * np.linalg.norm(w) + 1e-300), -1, 1)))
    return float(min(angles))


class _Blocks:
    """The feature points' (x, y) box cut into GRID x GRID blocks; outside points fall in the rim."""

    def __init__(self, points: np.ndarray) -> None:
        self.lo, self.hi = points[:, :2].min(axis=0), points[:, :2].max(axis=0)

    def cell(self, xy: np.ndarray) -> np.ndarray:
        return np.clip(((xy - self.lo) / (self.hi - self.lo) * GRID).astype(int), 0, GRID - 1)


def _snap(vertices: np.ndarray, skin: Skin, blocks: _Blocks, target: np.ndarray,
          anchors: list[int], taken: np.ndarray) -> int:
    """The skin vertex nearest ``target`` in its block (and the blocks around it) and within
    geodesic reach of the nearest frame point: twice the straight distance, plus a block; not one
    another feature point has ``taken`` (two on one vertex are two control points on one place:
    a face of another shape put the chin's 2.11 on 2.10's)."""
    verts = np.flatnonzero(skin.mask)
    verts = verts[~np.isin(verts, taken)]
    near = np.abs(blocks.cell(vertices[verts, :2]) - blocks.cell(target[:2])).max(axis=1) <= 1
    anchor = min(anchors, key=lambda a: (np.linalg.norm(vertices[a] - target), a))
    reach = 2 * np.linalg.norm(vertices[anchor] - target) + np.max((blocks.hi - blocks.lo) / GRID)
    geodesic = dijkstra(skin.graph, directed=False, indices=anchor, limit=reach)
    candidates = verts[near & np.isfinite(geodesic[verts])]
    if not len(candidates):
        candidates = verts
    return int(candidates[np.argmin(np.linalg.norm(vertices[candidates] - target, axis=1))])


def _pivots(vertices: np.ndarray, parts: dict[str, np.ndarray], fp: dict[str, np.ndarray],
            reference) -> dict[str, np.ndarray]:
    """Eyeball centres (box centre of the eyeball, else placed like a feature point), the jaw's
    and head's pivots placed from the default face, the jaw axis along x."""
    pivots = {"jaw_axis": np.array([1.0, 0.0, 0.0]), "head": fp["7.1"].copy()}
    known = sorted(set(fp) & set(reference.feature_points) - {"7.1", "11.5"})
    for name in ("eye_l", "eye_r", "jaw"):
        if name in parts:
            eye = vertices[parts[name]]
            pivots[name] = (eye.min(axis=0) + eye.max(axis=0)) / 2
        else:
            ids = _nearest_ids(reference.feature_points, reference.pivots[name], known, fp)
            pivots[name] = _placed(fp, reference.pivots[name], reference.feature_points, ids)
    return pivots


def _nearest_ids(reference: dict[str, np.ndarray], point: np.ndarray, known: list[str],
                 here: dict[str, np.ndarray]) -> list[str]:
    probe = dict(reference, _probe=np.asarray(point, float))
    return _frame_ids(probe, "_probe", known, here)
