"""Waters muscles as data: linear muscles and sphincters, where they sit on a face, and the default set.

Two kinds of muscle, both plain data (``muscles_to_json`` / ``muscles_from_json`` for the rig file):

* :class:`LinearMuscle` (Waters 1987): a fixed end ``m_o`` on the bone, an insertion ``m_i`` in
  the skin, a zone of half-angle ``alpha`` (degrees) about the axis m_o -> m_i, and the radial
  fall-off radii ``r_e`` and ``r_f`` (Waters' Rs and Rf). A point P at distance D = |P - m_o|,
  at angle mu from the axis, moves toward m_o by::

      u(P) = c * pull * A(mu) * R(D) * (m_o - P) / D
      A(mu) = cos(pi/2 * mu / alpha)              for mu < alpha, else 0
      R(D)  = sin(pi/2 * D / r_e)                 for D <= r_e       (Waters: cos((1 - D/Rs) pi/2))
            = cos(pi/2 * (D - r_e) / (r_f - r_e)) for r_e < D <= r_f, else 0

  c is the contraction (0..1 normal, larger for experiments) and ``pull`` the travel of a point at
  full effect at c = 1 (mesh units). Waters' own angular factor, cos(mu), jumps from cos(alpha)
  to 0 at the zone's edge and tears the skin there at any contraction; cos(pi/2 mu/alpha) is 1 on
  the axis like his and reaches 0 at the edge, so the only failure left is the one Zhou & Liu
  study: near m_o the pull grows faster than the distance (slope c pull pi / (2 r_e)), and once
  that slope passes 1 points are dragged past the fixed end: a spike, and triangles fold over.
* :class:`Sphincter` (Waters' elliptical sphincter): a centre and an ellipsoid of semi-axes
  ``radii`` along the face axes; with q the ellipsoidal distance (1 on the boundary), a point
  moves in the frontal (x, y) plane toward the centre by ``c * squeeze * F(q) * (centre - P)_xy``,
  F(q) = cos^2(pi/2 q) for q < 1: ``squeeze`` is the fraction of the way to the centre at c = 1.

Adaptive placement (Zhou & Liu): a muscle end is stored as coefficients in the basis of three
MPEG-4 feature points (``place`` / ``place_coefficients``), so the same recipe places it on any
face that has the feature points; ``default_muscles(face)`` does this for the default set and
puts each end on the nearest skin vertex (the muscle formulas use 3D distances to the ends, so an
end floating off the skin would shift every zone).

The muscle set, 9 pairs after Waters' face model (whose muscle table, as commonly reproduced,
has zygomatic major, angular depressor, frontalis inner / major / outer, levator labii superioris
("labi nasi"), levator labii superioris alaeque nasi ("inner labi nasi"), lateral corrugator and a
secondary frontalis strand). We keep the first eight; the secondary frontalis, a fourth strand
over the same forehead the three frontalis strands already raise, is replaced by the
**risorius**, so the lower face also gets a sideways lip-corner puller (FACS AU20; the FAPs
stretch_l/r_cornerlip), which Waters' set lacks. The sphincters are orbicularis oris (around the
lips' meeting point) and orbicularis oculi (around each eye). The jaw, the lower lip and the lids
proper are driven by FAPs and rigid parts, not muscles.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np


@dataclass
class LinearMuscle:
    """A Waters linear (vector) muscle; see the module docstring for the displacement it makes."""

    name: str
    fixed: np.ndarray  # m_o, (3,): the end on the bone
    insertion: np.ndarray  # m_i, (3,): the end in the skin
    alpha: float  # half-angle of the zone about the axis m_o -> m_i, degrees
    r_e: float  # Waters' Rs: the radial fall-off starts here (distance from m_o)
    r_f: float  # Waters' Rf: and reaches zero here
    pull: float  # travel at full effect for contraction 1, mesh units


@dataclass
class Sphincter:
    """A Waters elliptical sphincter: pulls toward ``center`` in the frontal plane."""

    name: str
    center: np.ndarray  # (3,)
    radii: np.ndarray  # (3,) semi-axes of the zone along the face's x, y, z
    squeeze: float  # share of the way to the centre a point near it travels at contraction 1


Muscle = LinearMuscle | Sphincter


# -- the displacement laws ----------------------------------------------------------------------

# -- adaptive placement ---------------------------------------------------------------------------

def _basis(corners: np.ndarray) -> np.ndarray:
    """Rows A, B - A, C - A and the triangle's normal scaled to its size (sqrt of twice the area),
    turned forward (+z) so that mirroring a face mirrors the basis."""
    a, b, c = corners
    n = np.cross(b - a, c - a)
    size = np.linalg.norm(n)
    n = n / np.sqrt(size) if size > 0 else n
    return np.array([a, b - a, c - a, -n if n[2] < 0 else n])


def place(feature_points: Mapping[str, np.ndarray], ids: Sequence[str], coefficients: Sequence[float]) -> np.ndarray:
    """The point w_a A + w_b B + w_c C + h n of the basis of feature points ``ids`` = (A, B, C),
    for ``coefficients`` (w_a, w_b, w_c, h): barycentric weights (normalised to sum 1) and an
    offset along the triangle's forward normal in units of the triangle's size. The same
    coefficients place the same anatomical point on another face (Zhou & Liu's adaptive muscles)."""
    basis = _basis(np.array([feature_points[i] for i in ids], dtype=float))
    wa, wb, wc, h = (float(x) for x in coefficients)
    total = wa + wb + wc
    return basis[0] + (wb * basis[1] + wc * basis[2]) / total + h * basis[3]


def place_coefficients(point: np.ndarray, feature_points: Mapping[str, np.ndarray], ids: Sequence[str]) -> np.ndarray:
    """The coefficients (w_a, w_b, w_c, h) that ``place`` turns back into ``point``: how a muscle
    end drawn on one face is written down for every face."""
    basis = _basis(np.array([feature_points[i] for i in ids], dtype=float))
    wb, wc, h = np.linalg.solve(basis[1:].T, np.asarray(point, float) - basis[0])
    return np.array([1.0 - wb - wc, wb, wc, h])


# -- the default muscles ----------------------------------------------------------------------------

# Left-side recipes (the face's own left, +x). An end is (feature point ids, (w_a, w_b, w_c, h));
# r_e and r_f are multiples of the muscle's length, pull a multiple of r_e (``PULL`` unless given).
# The levators and the inner frontalis pull less, and the levators have narrower zones, than the
# rest: at contraction 1 their zones drag the nostril's and the brow's control points hardest, and
# DFFD folded the nostril and the upper lip there (tools/checks/muscle_experiment.py: no muscle alone at
# c <= 1, nor all of them at 0.5, folds a triangle in the control-point mode without the guard).
LINEAR_RECIPES = {
    # name: (fixed end, insertion, alpha (deg), r_e / length, r_f / length[, pull / r_e])
    "zygomatic_major": ((("5.3", "10.7", "5.1"), (0.5, 0.35, 0.15, 0)),
                        (("8.3", "5.1", "8.5"), (0.85, 0.15, 0, 0)), 22, 1.0, 1.4),
    "depressor_anguli_oris": ((("2.11", "2.13", "2.1"), (0.75, 0.25, 0, 0)),
                              (("8.3", "8.7", "2.11"), (0.9, 0, 0.1, 0)), 25, 1.0, 1.4),
    "frontalis_inner": ((("11.1", "11.3", "4.1"), (0.75, 0.2, 0.05, 0)),
                        (("4.1", "11.1", "4.3"), (0.9, 0.1, 0, 0)), 18, 1.0, 1.3, 0.11),
    "frontalis_major": ((("11.3", "11.1", "4.3"), (0.55, 0.45, 0, 0)),
                        (("4.3", "11.3", "4.1"), (0.9, 0.1, 0, 0)), 18, 1.0, 1.3),
    "frontalis_outer": ((("11.3", "4.5", "11.1"), (0.9, 0.1, 0, 0)),
                        (("4.5", "11.3", "3.7"), (0.9, 0.1, 0, 0)), 18, 1.0, 1.3),
    "levator_labii_superioris": ((("3.9", "5.3", "9.13"), (0.3, 0.4, 0.3, 0)),
                                 (("8.5", "9.1", "8.3"), (0.8, 0.2, 0, 0)), 12, 1.0, 1.3, 0.12),
    "levator_labii_alaeque_nasi": ((("9.7", "3.11", "9.13"), (0.4, 0.4, 0.2, 0)),
                                   (("9.1", "8.5", "9.5"), (0.6, 0.4, 0, 0)), 15, 1.0, 1.3, 0.09),
    "corrugator_supercilii": ((("4.1", "9.7", "3.11"), (0.3, 0.6, 0.1, 0)),
                              (("4.3", "4.1", "3.13"), (0.7, 0.3, 0, 0)), 20, 1.0, 1.4),
    "risorius": ((("2.13", "5.1", "10.7"), (0.5, 0.4, 0.1, 0)),
                 (("8.3", "5.1", "8.7"), (0.95, 0.05, 0, 0)), 20, 1.0, 1.3),
}
PULL = 0.15  # a linear muscle's pull at contraction 1, as a share of its r_e
SPHINCTER_RECIPES = {
    # name: (centre, (feature points whose distance scales the radii), radii / that distance, squeeze)
    "orbicularis_oris": ((("2.2", "2.3", "8.3"), (0.5, 0.5, 0, 0)), ("8.3", "8.4"), (0.7, 0.45, 0.5), 0.2),
    "orbicularis_oculi_l": ((("3.5", "3.7", "3.11"), (1, 0, 0, 0)), ("3.7", "3.11"), (1.15, 0.95, 0.8), 0.35),
}
# Feature point ids of the face's left side and their mirror on the right (MPEG-4 numbering is
# not a plain odd/even rule: 3.7 pairs with 3.12, 8.10 with 8.9, ...); ids on the mid-line are
# their own mirror.
MIRROR_IDS = {
    "2.4": "2.5", "2.6": "2.7", "2.8": "2.9", "2.11": "2.12", "2.13": "2.14", "3.1": "3.2", "3.3": "3.4",
    "3.5": "3.6", "3.7": "3.12", "3.9": "3.10", "3.11": "3.8", "3.13": "3.14", "4.1": "4.2", "4.3": "4.4",
    "4.5": "4.6", "5.1": "5.2", "5.3": "5.4", "8.3": "8.4", "8.5": "8.6", "8.7": "8.8", "8.10": "8.9",
    "9.1": "9.2", "9.5": "9.4", "9.7": "9.6", "9.13": "9.14", "10.7": "10.8", "10.9": "10.10", "11.3": "11.2",
}
MIRROR_IDS |= {v: k for k, v in MIRROR_IDS.items()}


def _same(fid: str) -> str:
    return fid


def _mirrored(fid: str) -> str:
    return MIRROR_IDS.get(fid, fid)


def _default_set() -> list[tuple[str, str, tuple, Callable[[str], str]]]:
    """(name, "linear" | "sphincter", recipe, feature point renaming) of every default muscle, in
    order: each linear muscle's left then right strand, then the sphincters (a ``_l`` one followed
    by its mirror)."""
    out = []
    for name, recipe in LINEAR_RECIPES.items():
        out += [(f"{name}_l", "linear", recipe, _same), (f"{name}_r", "linear", recipe, _mirrored)]
    for name, recipe in SPHINCTER_RECIPES.items():
        out.append((name, "sphincter", recipe, _same))
        if name.endswith("_l"):
            out.append((name[:-2] + "_r", "sphincter", recipe, _mirrored))
    return out


DEFAULT_SET = _default_set()
MUSCLE_NAMES = tuple(name for name, *_ in DEFAULT_SET)
"""The default muscles' names, in rig order: what a mapping's ``muscle:`` targets may name."""


def default_muscles(face) -> list[Muscle]:
    """The default muscle set (module docstring) placed on ``face`` by its feature points: 9 pairs
    of linear muscles named ``<muscle>_l`` / ``_r`` and the three sphincters, ends on the skin
    (``MUSCLE_NAMES``, in that order). A muscle whose feature points the face lacks is left out
    (a face rigged from fewer landmarks still gets the muscles it can place)."""
    fp = {k: np.asarray(v, float) for k, v in face.feature_points.items()}
    skin = np.asarray(face.vertices, float)[face.parts.get("skin", np.arange(len(face.vertices)))]
    muscles: list[Muscle] = []
    for name, kind, recipe, rename in DEFAULT_SET:
        if not all(rename(i) in fp for i in _recipe_ids(kind, recipe)):
            continue
        if kind == "linear":
            muscles.append(_linear_from_recipe(name, recipe, fp, skin, rename))
        else:
            muscles.append(_sphincter_from_recipe(name, recipe, fp, rename))
    return muscles


def _recipe_ids(kind: str, recipe: tuple) -> set[str]:
    """The feature point ids a recipe places its muscle by."""
    if kind == "linear":
        (fixed_ids, _), (ins_ids, _), *_ = recipe
        return {*fixed_ids, *ins_ids}
    (ids, _), scale_ids, *_ = recipe
    return {*ids, *scale_ids}


def _on_skin(point: np.ndarray, skin: np.ndarray) -> np.ndarray:
    return skin[np.argmin(np.einsum("ij,ij->i", skin - point, skin - point))].copy()


def _linear_from_recipe(name: str, recipe: tuple, fp: Mapping[str, np.ndarray], skin: np.ndarray,
                        rename: Callable[[str], str]) -> LinearMuscle:
    (fixed_ids, fixed_w), (ins_ids, ins_w), alpha, r_e, r_f, *pull = recipe
    fixed = _on_skin(place(fp, [rename(i) for i in fixed_ids], fixed_w), skin)
    insertion = _on_skin(place(fp, [rename(i) for i in ins_ids], ins_w), skin)
    length = float(np.linalg.norm(insertion - fixed))
    return LinearMuscle(name, fixed, insertion, float(alpha), r_e * length, r_f * length,
                        (pull[0] if pull else PULL) * r_e * length)


def _sphincter_from_recipe(name: str, recipe: tuple, fp: Mapping[str, np.ndarray],
                           rename: Callable[[str], str]) -> Sphincter:
    (ids, weights), (p, q), radii, squeeze = recipe
    scale = float(np.linalg.norm(fp[rename(p)] - fp[rename(q)]))
    center = place(fp, [rename(i) for i in ids], weights)
    return Sphincter(name, center, scale * np.asarray(radii, float), float(squeeze))


def flat_grid(n: int = 41) -> tuple[np.ndarray, np.ndarray]:
    """The paper's experiment mesh: vertices (n*n, 3) on [-0.5, 0.5]^2 at z = 0 and triangles
    (2 (n-1)^2, 3), counter-clockwise seen from +z."""
    x = np.linspace(-0.5, 0.5, n)
    gx, gy = np.meshgrid(x, x)
    vertices = np.c_[gx.ravel(), gy.ravel(), np.zeros(n * n)]
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    return vertices, np.r_[np.c_[a, a + 1, a + n + 1], np.c_[a, a + n + 1, a + n]]


def mirror_muscle(m: Muscle, name: str | None = None) -> Muscle:
    """The muscle mirrored across the plane x = 0 (the face's mid-line)."""
    flip = np.array([-1.0, 1.0, 1.0])
    if isinstance(m, LinearMuscle):
        return LinearMuscle(name or m.name, m.fixed * flip, m.insertion * flip, m.alpha, m.r_e, m.r_f, m.pull)
    return Sphincter(name or m.name, m.center * flip, m.radii.copy(), m.squeeze)


# -- JSON -------------------------------------------------------------------------------------------

def muscles_to_json(muscles: Sequence[Muscle]) -> list[dict]:
    """Plain JSON data (lists of floats) for the rig file."""
    out = []
    for m in muscles:
        if isinstance(m, LinearMuscle):
            out.append({"kind": "linear", "name": m.name, "fixed": _floats(m.fixed), "insertion": _floats(m.insertion),
                        "alpha": float(m.alpha), "r_e": float(m.r_e), "r_f": float(m.r_f), "pull": float(m.pull)})
        else:
            out.append({"kind": "sphincter", "name": m.name, "center": _floats(m.center),
                        "radii": _floats(m.radii), "squeeze": float(m.squeeze)})
    return out


def muscles_from_json(obj: Sequence[Mapping]) -> list[Muscle]:
    """Muscles from ``muscles_to_json`` data; a bad entry raises ValueError naming it."""
    muscles: list[Muscle] = []
    for i, entry in enumerate(obj):
        try:
            muscles.append(_muscle_from_dict(entry))
        except (KeyError, TypeError, ValueError) as exc:
            name = entry.get("name", "?") if isinstance(entry, Mapping) else "?"
            raise ValueError(f"muscle #{i} ({name}): {type(exc).__name__}: {exc}") from exc
    return muscles


def _muscle_from_dict(d: Mapping) -> Muscle:
    kind = d["kind"]
    if kind == "linear":
        m = LinearMuscle(str(d["name"]), _vec(d["fixed"]), _vec(d["insertion"]), float(d["alpha"]),
                         float(d["r_e"]), float(d["r_f"]), float(d["pull"]))
        if not (0 < m.r_e < m.r_f and 0 < m.alpha < 180):
            raise ValueError("needs 0 < r_e < r_f and 0 < alpha < 180")
        return m
    if kind == "sphincter":
        s = Sphincter(str(d["name"]), _vec(d["center"]), _vec(d["radii"]), float(d["squeeze"]))
        if not np.all(s.radii > 0):
            raise ValueError("radii must be positive")
        return s
    raise ValueError(f"kind {kind!r}: expected 'linear' or 'sphincter'")


def _vec(x) -> np.ndarray:
    v = np.asarray(x, dtype=float)
    if v.shape != (3,):
        raise ValueError(f"expected 3 numbers, got {x!r}")
    return v


def _floats(v: np.ndarray) -> list[float]:
    return [float(x) for x in v]
