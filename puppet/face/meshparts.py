"""A face's parts from the pieces its file is made of: meshes, primitives, OBJ groups and materials.

An artist's head comes in pieces: the skin, two eyeballs (often sclera and iris apart), teeth,
a tongue, lashes and brows. The rig needs the default face's parts (``eye_l``, ``eye_r``,
``teeth_upper``, ``teeth_lower``, ``tongue``, and ``skin`` for all the rest) so eyes turn and
teeth stay rigid; :func:`name_parts` finds them.

* **By name**: the piece's mesh, node, material and group names, lower-cased, read together.
  ``ATTACHED_WORDS`` (``lash``, ``brow``, ``occlusion``, ``lacrimal``, ``tear``, ...) name things
  that ride the skin: part ``attached`` (``puppet.face.autorig`` moves it with the skin under it).
  Then ``tongue`` the tongue (but not with ``gum``: gums and tongue in one piece are left to the
  landmarks' mouth finder, ``puppet.face.landmarks``); ``teeth``, ``tooth`` teeth (``upper`` /
  ``top`` or ``lower`` / ``bottom`` say which row, else its connected pieces are sorted into rows,
  so no tooth is cut: ``_split_teeth``); ``eye``, ``sclera``, ``iris``, ``cornea``, ``pupil`` an
  eyeball (but not with ``lid`` or ``socket``: skin).
* **By shape**, when no piece is named an eye: two roughly spherical connected pieces outside
  the largest piece, level with each other either side of its mid-line, in its upper half.
* **Sides**: an eyeball vertex right of the largest piece's mid-line (+x, the face's own left in
  the face frame) is ``eye_l``, else ``eye_r``.

A vertex that any unrecognised piece uses is skin: an eye piece stitched to the skin stays skin.

Pieces named as see-through overlays (``OVERLAY_WORDS``: ICT-FaceKit's eye occlusion and eye
blend shells, which cover the whole eye opening and are meant to be blended over it) cannot be
drawn as the artist meant by an opaque renderer: drawn opaque they hide the eyeballs. They are
``attached`` and :func:`overlay_vertices` says which vertices they hold, so a loader can leave
their triangles out. So are the cornea caps of an eyeball whose white (``sclera``, ``eyewhite``)
is a whole ball around its ``iris`` (ICT-FaceKit's: the artist's engine sees through the cap by
a texture's alpha; drawn opaque it hides the iris): :func:`cornea_vertices`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

OVERLAY_WORDS = ("occlusion", "eyeblend", "eye_blend", "shadow")
ATTACHED_WORDS = ("lash", "brow", "occlusion", "eyeblend", "eye_blend", "lacrimal", "tear", "shadow", "eyeline",
                  "eye_line", "eyeextra", "eye_extra")
SKIN_WORDS = ("lid", "socket")  # an eyelid or eye socket piece is skin, for all it says "eye"
WHITE_WORDS = ("sclera", "eyewhite", "eye_white")
EYE_WORDS = ("eye", "sclera", "iris", "cornea", "pupil")
TEETH_WORDS = ("teeth", "tooth")
UPPER_WORDS, LOWER_WORDS = ("upper", "top"), ("lower", "bottom")
ROUNDNESS = 0.6  # a spherical piece's smallest box side over its largest, at least
CORNEA_ANGLE = 29.0  # degrees: the cornea's half-angle seen from the eyeball's centre (11.5 of 24 mm)
LEVEL = 0.25  # two eyeballs' heights and sizes differ by at most this share of their size


class Piece(NamedTuple):
    """A piece of a face file: its names read together and the vertices it uses."""

    names: str
    vertices: np.ndarray  # int vertex indices into the face


def name_parts(vertices: np.ndarray, triangles: np.ndarray, pieces: list[Piece]) -> dict[str, np.ndarray]:
    """{part: sorted int32 vertex indices} over all of ``vertices`` (module docstring)."""
    n = len(vertices)
    label = np.full(n, "", dtype=object)
    skin = np.zeros(n, dtype=bool)
    for piece in pieces:
        kind = _kind(piece.names.lower())
        if kind:
            label[piece.vertices] = np.where(label[piece.vertices] == "", kind, label[piece.vertices])
        else:
            skin[piece.vertices] = True
    label[skin] = ""
    if not (label == "eye").any():
        largest = max(pieces, key=lambda p: len(p.vertices)).vertices if pieces else np.arange(n)
        label[_eyes_by_shape(vertices, triangles, largest, label == "")] = "eye"
    mid = _mid_x(vertices, pieces)
    eye = label == "eye"
    label[eye] = np.where(vertices[eye, 0] >= mid, "eye_l", "eye_r")
    _split_teeth(vertices, triangles, label)
    label[label == ""] = "skin"
    return {name: np.flatnonzero(label == name).astype(np.int32) for name in sorted(set(label))}


def overlay_vertices(n: int, pieces: list[Piece]) -> np.ndarray:
    """(n,) bool: the vertices of pieces named as see-through overlays (module docstring)."""
    out = np.zeros(n, dtype=bool)
    for piece in pieces:
        if any(w in piece.names.lower() for w in OVERLAY_WORDS):
            out[piece.vertices] = True
    return out


def cornea_vertices(vertices: np.ndarray, pieces: list[Piece]) -> np.ndarray:
    """(n,) bool: the vertices of eye whites in front of an iris that the white encloses: those
    seen from the white's centre within the iris's cone, or within ``CORNEA_ANGLE`` of +z when
    the iris is a whole ball too (module docstring)."""
    out = np.zeros(len(vertices), dtype=bool)
    whites = [p.vertices for p in pieces if any(w in p.names.lower() for w in WHITE_WORDS)]
    for iris in (p.vertices for p in pieces if "iris" in p.names.lower()):
        centre_of_iris = vertices[iris].mean(axis=0)
        for white in whites:
            low, high = vertices[white].min(axis=0), vertices[white].max(axis=0)
            if not ((low <= centre_of_iris) & (centre_of_iris <= high)).all():
                continue
            centre = (low + high) / 2
            axis = centre_of_iris - centre
            ball = np.linalg.norm(axis) < 0.25 * np.linalg.norm(high - low) / 2
            axis = np.array([0.0, 0.0, 1.0]) if ball else axis / np.linalg.norm(axis)
            cone = np.cos(np.radians(CORNEA_ANGLE)) if ball else (_unit(vertices[iris] - centre) @ axis).min()
            out[white[_unit(vertices[white] - centre) @ axis > cone]] = True
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    return v / (np.linalg.norm(v, axis=1, keepdims=True) + 1e-300)


def _kind(names: str) -> str:
    """What a piece's names (lower case) say it is: a part name, ``eye`` or ``teeth`` (sided or
    split later), or "" (skin)."""
    if any(w in names for w in ATTACHED_WORDS):
        return "attached"
    if "tongue" in names and "gum" not in names:
        return "tongue"
    if any(w in names for w in TEETH_WORDS):
        if any(w in names for w in UPPER_WORDS):
            return "teeth_upper"
        return "teeth_lower" if any(w in names for w in LOWER_WORDS) else "teeth"
    if any(w in names for w in EYE_WORDS) and not any(w in names for w in SKIN_WORDS):
        return "eye"
    return ""


def _mid_x(vertices: np.ndarray, pieces: list[Piece]) -> float:
    largest = max(pieces, key=lambda p: len(p.vertices)).vertices if pieces else slice(None)
    x = vertices[largest, 0]
    return float(x.min() + x.max()) / 2


def components(n: int, triangles: np.ndarray, seams: np.ndarray | None = None) -> np.ndarray:
    """Per vertex of ``n``, its connected component's label; ``seams`` (pairs of vertices) are
    joined too."""
    t = np.asarray(triangles, dtype=np.int64)
    rows, cols = np.r_[t[:, 0], t[:, 1], t[:, 2]], np.r_[t[:, 1], t[:, 2], t[:, 0]]
    if seams is not None and len(seams):
        rows, cols = np.r_[rows, seams[:, 0]], np.r_[cols, seams[:, 1]]
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _eyes_by_shape(vertices: np.ndarray, triangles: np.ndarray, largest: np.ndarray,
                   free: np.ndarray) -> np.ndarray:
    """The vertices of the two eyeball-like components (module docstring), none if no pair."""
    comp = components(len(vertices), triangles)
    outside = free.copy()
    outside[largest] = False
    if not outside.any():
        return np.zeros(len(vertices), dtype=bool)
    head = vertices[largest]
    mid_x, mid_y = (head[:, 0].min() + head[:, 0].max()) / 2, (head[:, 1].min() + head[:, 1].max()) / 2
    balls = []
    for c in np.unique(comp[outside]):
        members = comp == c
        if members.sum() < 8 or not (outside | ~members).all():
            continue
        p = vertices[members]
        size = np.ptp(p, axis=0)
        centre = (p.min(axis=0) + p.max(axis=0)) / 2
        if size.max() > 0 and size.min() / size.max() >= ROUNDNESS and centre[1] > mid_y:
            balls.append((c, centre, float(size.max())))
    pairs = [(a, b) for i, a in enumerate(balls) for b in balls[i + 1:]
             if (a[1][0] - mid_x) * (b[1][0] - mid_x) < 0
             and abs(a[1][1] - b[1][1]) < LEVEL * max(a[2], b[2]) and abs(a[2] - b[2]) < LEVEL * max(a[2], b[2])]
    if not pairs:
        return np.zeros(len(vertices), dtype=bool)
    a, b = max(pairs, key=lambda pair: pair[0][2] + pair[1][2])
    return (comp == a[0]) | (comp == b[0])


def _split_teeth(vertices: np.ndarray, triangles: np.ndarray, label: np.ndarray) -> None:
    """Unqualified ``teeth`` vertices to upper and lower rows, a whole component at a time: above or
    below the line that best fits the components' mean heights against their depth (both rows rise
    toward the back of the mouth, so height alone mixes them)."""
    teeth = np.flatnonzero(label == "teeth")
    if not len(teeth):
        return
    comp = np.unique(components(len(vertices), triangles)[teeth], return_inverse=True)[1]
    count = np.bincount(comp)
    y, z = (np.bincount(comp, weights=vertices[teeth, k]) / count for k in (1, 2))
    if len(count) > 2:
        slope, offset = np.polyfit(z, y, 1, w=np.sqrt(count))
        upper = (y - (slope * z + offset))[comp] > 0
    else:  # one piece holding both rows, or one piece a row: split at the middle of the height
        height = vertices[teeth, 1]
        upper = (y[comp] if len(count) == 2 else height) >= (height.min() + height.max()) / 2
    label[teeth] = np.where(upper, "teeth_upper", "teeth_lower")
