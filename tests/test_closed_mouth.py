"""A face whose lips are one sheet of skin (a scan with a closed mouth: no opening, no mouth bag,
the lips' meeting line a row of vertices both lips share) parts its lips with a smooth edge: the
row where they join moves as one line, never torn vertex by vertex between the two lips
(puppet.face.autorig, ``_closed_mouth``)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from puppet.face.autorig import _loop_path_via, build_rig
from puppet.face.load import load_face
from puppet.face.meshfile import write_bare_obj
from puppet.runtime.runtime import Runtime

POSES = {"open_jaw": {"fap": {"open_jaw": 400}}, "fear": {"expression": (4, 63, 0, 0)},
         "surprise": {"expression": (6, 63, 0, 0)}}
UPPER_INNER, LOWER_INNER = ("2.2", "2.6", "2.7"), ("2.3", "2.8", "2.9")


def _lip_rows(face) -> tuple[list[int], list[int]]:
    """The default face's inner lip rows, corner 2.5 to corner 2.4: the upper and the lower."""
    loop = [int(i) for i in face.contours["mouth_opening"]]
    fv = face.feature_vertices
    a, b = loop.index(fv["2.5"]), loop.index(fv["2.4"])
    return _loop_path_via(loop, a, b, fv["2.2"]), _loop_path_via(loop, a, b, fv["2.3"])


def _mouth_inside(face) -> np.ndarray:
    """Per vertex, whether it is the mouth's inside: the bag behind the lips, the teeth, the tongue."""
    n = len(face.vertices)
    skin, lips = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    skin[face.parts["skin"]] = lips[face.contours["mouth_opening"]] = True
    t = face.triangles
    e = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e = e[skin[e].all(axis=1) & ~lips[e].any(axis=1)]
    piece = connected_components(sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)),
                                 directed=False)[1]
    inside = skin & ~lips & (piece != piece[face.feature_vertices["9.3"]])
    for part in ("teeth_upper", "teeth_lower", "tongue"):
        inside[face.parts[part]] = True
    return inside


def _welded(face) -> np.ndarray:
    """Per vertex, the vertex it becomes when the lower inner lip row is welded onto the upper one:
    each lower vertex onto the upper vertex nearest it across, the upper vertices left between them
    onto their nearest welded neighbour along the row (an edge collapse), so the row stays manifold."""
    upper, lower = (np.array(row[1:-1]) for row in _lip_rows(face))
    x = face.vertices[:, 0]
    match = [int(np.argmin(np.abs(x[upper] - x[j]))) for j in lower]
    assert len(set(match)) == len(match)
    target = np.arange(len(face.vertices))
    for k, u in enumerate(upper):
        target[u] = upper[min(match, key=lambda m: abs(m - k))]
    target[lower] = upper[match]
    return target


@pytest.fixture(scope="module")
def closed(tmp_path_factory):
    """The default face with its lips welded into one sheet and its mouth's inside dropped, written
    as a bare OBJ and loaded from landmarks that put the inner lip points a row off the seam, the
    upper ones above it and the lower ones below (as a user marks the lips' edges on a closed
    mouth): the face, its rig's runtime and the seam's vertices from corner to corner."""
    face = load_face()
    target = _welded(face)
    tri = target[face.triangles]
    distinct = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 2] != tri[:, 0])
    tri = tri[distinct & ~_mouth_inside(face)[tri].any(axis=1)]
    used = np.zeros(len(face.vertices), dtype=bool)
    used[tri] = True
    new = np.cumsum(used) - 1
    mesh = write_bare_obj(tmp_path_factory.mktemp("closed") / "closed.obj", face.vertices[used], new[tri])
    upper = np.array(_lip_rows(face)[0])
    seam = new[upper[used[upper]]]
    landmarks = {f: int(new[target[v]]) for f, v in face.feature_vertices.items() if used[target[v]]}
    _off_the_seam(landmarks, face.vertices[used], new[tri], seam)
    closed = load_face(mesh, landmarks=landmarks)
    return closed, Runtime(closed, build_rig(closed), cache=False), seam[np.argsort(closed.vertices[seam, 0])]


def _off_the_seam(landmarks: dict[str, int], v: np.ndarray, tri: np.ndarray, seam: np.ndarray) -> None:
    """Move the inner lip points from the seam to their neighbour off it, above or below."""
    on_seam = np.zeros(len(v), dtype=bool)
    on_seam[seam] = True
    for fdp in UPPER_INNER + LOWER_INNER:
        near = np.unique(tri[(tri == landmarks[fdp]).any(axis=1)])
        near = near[~on_seam[near]]
        sign = 1 if fdp in UPPER_INNER else -1
        landmarks[fdp] = int(near[np.argmax(sign * v[near, 1] - 0.3 * np.abs(v[near, 0] - v[landmarks[fdp], 0]))])


def test_the_welded_face_has_no_mouth_opening(closed):
    """The lips are one sheet: each vertex of the seam but its corners is an edge's end on both
    lips, one above it and one below, and nothing is left inside the mouth."""
    face, _, seam = closed
    assert len(seam) >= 10
    assert set(face.parts) == {"skin", "eye_l", "eye_r"}
    y = face.vertices[:, 1]
    for vertex in seam[1:-1]:
        near = np.unique(face.triangles[(face.triangles == vertex).any(axis=1)])
        assert y[near].max() > y[vertex] > y[near].min()


@pytest.mark.parametrize("pose", POSES)
def test_a_closed_mouth_parts_with_its_seam_a_smooth_line(closed, pose):
    """Posed, the seam's vertices move as one line: the vertical step between neighbours stays under
    half of how far the lips part (0.13-0.32 of it: the upper lip's own curve; it was 0.71-0.84, the
    middle of the seam torn down with the lower lip and its ends left with the upper), and no vertex
    moves past both its neighbours by more than 0.04 of it (0.02 at most; it was 0.06-0.22)."""
    face, runtime, seam = closed
    moved = runtime.deform_faps(**POSES[pose]) - face.vertices
    fv = face.feature_vertices
    opening = moved[fv["2.2"], 1] - moved[fv["2.3"], 1]
    dy = moved[seam, 1]
    assert opening > 0.02 * np.ptp(face.vertices[seam, 0])
    assert np.abs(np.diff(dy)).max() < 0.5 * opening
    past = np.maximum(dy[1:-1] - np.maximum(dy[:-2], dy[2:]), np.minimum(dy[:-2], dy[2:]) - dy[1:-1])
    assert past.max() < 0.04 * opening
