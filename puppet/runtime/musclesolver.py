"""The muscle solver: how Waters muscles (``puppet.face.muscles``, Waters' formulas there) move a face.

Three ways to apply them:

* **Classic** (``MuscleModel(..., mode="classic")``): Waters' formulas (``puppet.face.muscles``) on every vertex, summed
  over muscles; one sparse product per frame.
* **Improved** (``mode="improved"``, after Zhou & Liu; their equations are not reproduced here, so
  these are our forms). (1) A *repulsive spring* at the attractor (the fixed end, or the
  sphincter's centre). Along its ray a vertex at rest distance D is pulled by the muscle with
  unit stiffness toward its classic place (travel u); once it comes within D/2 of the bone, a
  spring pushes it back with force ``F(rho) = (D/2 - rho)^2 / rho`` (rho: its distance to the bone
  now), whose stiffness ``-dF/drho = (D/2)^2 / rho^2 - 1`` rises as 1/rho^2 toward the bone. The
  balance ``u - (D - rho) = F(rho)`` solves in closed form::

      rho = D - u          for u <= D/2   (exactly the classic motion)
      rho = D^2 / (4 u)    for u >  D/2   (C1 at u = D/2; rho > 0 for any u)

  so ordinary contractions are untouched (at c = 1 no point goes half way to its bone) and no
  vertex reaches the fixed end: the spike is gone. Along a ray, rho(D) stays increasing for any
  contraction wherever the classic travel is concave in D (inside r_e, where Waters' sine
  fall-off is) or decreasing (beyond r_e), so the rays cannot fold either (a triangle spanning
  several rays still can, where the zone is squeezed hard near the bone).
  (2) *Edge constraints* (:class:`EdgeConstraints`): for every triangle corner, a spring from the
  vertex to the opposite edge keeps the corner's height above that edge (measured in the plane
  normal to the triangle's rest normal) at least ``EDGE_MIN_HEIGHT`` of its rest height. It is
  compression-only, so ordinary motion is untouched (nothing is done unless a corner is below
  that floor). Where two muscles' fields, or the surface's curvature, squeeze a triangle, a few
  vectorised Jacobi sweeps (position-based: each violated constraint moves the vertex and the two
  edge ends along the edge's in-plane normal by inverse-mass-weighted shares, averaged per vertex)
  on the squeezed triangles and ``EDGE_RINGS`` rings around them push it back; if that is not
  enough (far beyond the normal contraction the zone is squeezed against the bone harder than any
  arrangement of the springs there allows), the displacement is scaled back toward rest around the
  squeezed triangles (by ``EDGE_DAMP`` there, less in the rings around, repeated) until no corner
  is below its floor. The rest mesh satisfies every constraint, so this always ends, and a triangle folds
  exactly when a corner crosses its opposite edge: the improved mode folds no skin triangle at
  any contraction.
* **Control points** (``control_point_displacements``, Zhang & Chen): the muscles move the rig's
  active control points inside their zones, and DFFD spreads that over the skin. The points move
  by the improved law (1): a control point that crossed its muscle's fixed end would turn the
  whole region it controls inside out, and there is no mesh between control points to hold it.
  That alone does not keep the skin from folding at large contraction (tools/checks/muscle_experiment.py:
  the zone squeezed toward the bone flips spread triangles on a grid at c = 5 and 10, and on the
  default face DFFD folds the rig's region borders next to the moving lip corner from c = 3);
  ``EdgeConstraints`` run on the spread displacement removes those folds. Without that guard no
  default muscle alone squeezes the skin at c <= 0.5 (the lid margin's points near the still eye
  corners take their share of the lid's turn: ``ControlPointMuscles``); at 1 the risorius and the
  orbicularis oculi fold a triangle each, at the lip and outer eye corners, and all of them at 0.5
  the two lip corners': the guard's work in a moving frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import scipy.sparse as sp

from puppet.face.muscles import LinearMuscle, Muscle, Sphincter

MODES = ("classic", "improved")
EDGE_MIN_HEIGHT = 0.05  # edge constraints keep a corner's height above this share of its rest height
EDGE_ITERATIONS = 8  # most relaxation sweeps per fix (they stop as soon as nothing is squeezed)
EDGE_RINGS = 2  # rings of triangles around the squeezed ones whose vertices the sweeps may move
EDGE_TARGET = 1.5  # a squeezed corner is pushed to this multiple of its floor
EDGE_OVERRELAX = 1.0  # the sweeps' averaged corrections are scaled by this (1: plain averaged Jacobi)
EDGE_DAMP = 0.75  # the fallback shrinks a squeezed triangle's vertices' displacement by this factor
EDGE_DAMP_STEPS = 12  # this many times at most, then drops it
EDGE_DAMP_RINGS = (0.85, 0.95)  # and the rings of vertices around them by these factors
SAFE_MARGIN = 0.999  # a triangle's reach (EdgeConstraints._reach) is used a hair short of the bound



def _linear_field(m: LinearMuscle, points: np.ndarray):
    """(rows, unit direction to m_o, classic travel per unit contraction, D) for the points inside
    the muscle's zone."""
    axis = np.asarray(m.insertion, float) - np.asarray(m.fixed, float)
    rel = points - np.asarray(m.fixed, float)
    dist = np.linalg.norm(rel, axis=1)
    cos_mu = rel @ axis / np.maximum(dist * np.linalg.norm(axis), 1e-300)
    mu = np.arccos(np.clip(cos_mu, -1.0, 1.0))
    alpha = np.radians(m.alpha)
    rows = np.flatnonzero((dist > 0) & (dist < m.r_f) & (mu < alpha))
    d, angle = dist[rows], mu[rows]
    radial = np.where(d <= m.r_e, np.sin(0.5 * np.pi * d / m.r_e),
                      np.cos(0.5 * np.pi * (d - m.r_e) / (m.r_f - m.r_e)))
    travel = m.pull * np.cos(0.5 * np.pi * angle / alpha) * radial
    direction = -rel[rows] / d[:, None]
    return rows, direction, travel, d


def _sphincter_field(s: Sphincter, points: np.ndarray):
    """The same four arrays for a sphincter (travel per unit contraction, toward the centre in x, y)."""
    rel = points - np.asarray(s.center, float)
    q = np.linalg.norm(rel / np.asarray(s.radii, float), axis=1)
    flat = rel.copy()
    flat[:, 2] = 0.0
    dist = np.linalg.norm(flat, axis=1)
    rows = np.flatnonzero((q < 1.0) & (dist > 0))
    d, qq = dist[rows], q[rows]
    travel = s.squeeze * np.cos(0.5 * np.pi * qq) ** 2 * d
    return rows, -flat[rows] / d[:, None], travel, d


def _field(m: Muscle, points: np.ndarray):
    return _linear_field(m, points) if isinstance(m, LinearMuscle) else _sphincter_field(m, points)


def repelled_travel(travel: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """The improved law's travel toward the attractor for classic travel ``travel`` at rest distance
    ``dist``: unchanged up to dist / 2, then dist - dist^2 / (4 travel) (the repulsive spring's
    balance, module docstring), always below ``dist``."""
    return np.where(travel <= 0.5 * dist, travel, dist - dist * dist / np.maximum(4.0 * travel, 1e-300))


def control_point_displacements(muscles: Sequence[Muscle], contractions: Mapping[str, float],
                                points: np.ndarray, shares: np.ndarray | None = None) -> np.ndarray:
    """Displacements (n, 3) of control points (n, 3) for muscle contractions {name: c}: each muscle
    moves the points inside its zone by the improved law (no point crosses its fixed end), each
    point by its share (``ControlPointMuscles``); the caller spreads them over the skin (DFFD,
    ``Runtime.deform``)."""
    return ControlPointMuscles(muscles, points, shares).displace(contractions)


class ControlPointMuscles:
    """``control_point_displacements`` for one fixed set of points, their fields computed once
    (the runtime's control-point mode). Every (muscle, point in its zone) pair is one entry of
    flat arrays, summed per point by one sparse product: a frame is a handful of whole-array
    steps however many muscles contract.

    ``shares`` (n, default all 1): the part of a muscle's motion each point takes. The runtime
    gives the lid margin's points their share of the lid's turn (``fapengine.lid_shares``), as
    the lid FAPs move them: near the eye corners, which the canthal tendons hold still, a point
    moved in full beside a still corner vertex turned the skin between them inside out (the
    orbicularis oculi from contraction 0.5)."""

    def __init__(self, muscles: Sequence[Muscle], points: np.ndarray, shares: np.ndarray | None = None) -> None:
        self.muscles = list(muscles)
        self.points = np.asarray(points, dtype=float)
        self._column = {m.name: j for j, m in enumerate(self.muscles)}
        fields = [_field(m, self.points) for m in self.muscles]
        self._rows = np.concatenate([np.zeros(0, np.int64), *(f[0] for f in fields)])
        self._muscle = np.concatenate([np.zeros(0, np.int64), *(np.full(len(f[0]), j) for j, f in enumerate(fields))])
        self._direction = np.concatenate([np.zeros((0, 3)), *(f[1] for f in fields)])
        self._travel = np.concatenate([np.zeros(0), *(f[2] for f in fields)])
        self._dist = np.concatenate([np.zeros(0), *(f[3] for f in fields)])
        share = np.ones(len(self.points)) if shares is None else np.asarray(shares, dtype=float)
        self._sum = sp.csr_matrix((share[self._rows], (self._rows, np.arange(len(self._rows)))),
                                  shape=(len(self.points), len(self._rows)))

    def moved(self) -> np.ndarray:
        """Indices of the points some muscle moves."""
        return np.unique(self._rows)

    def contractions(self, contractions: Mapping[str, float]) -> np.ndarray:
        """{name: c} as one value per muscle, in order (0 for those not named); an unknown name
        is an error that lists the known."""
        c = np.zeros(len(self.muscles))
        for name, value in contractions.items():
            j = self._column.get(name)
            if j is None:
                _contracting(self.muscles, contractions)  # raises, naming the unknown
            c[j] = value
        return c

    def displace(self, contractions: Mapping[str, float], out: np.ndarray | None = None) -> np.ndarray:
        """Displacements (n, 3) for contractions {name: c}, added to ``out`` when given."""
        moved = self.displaced(self.contractions(contractions))
        if out is None:
            return moved
        out += moved
        return out

    def displaced(self, c: np.ndarray) -> np.ndarray:
        """Displacements (n, 3) for one contraction per muscle, in order (``contractions``)."""
        travel = repelled_travel(c[self._muscle] * self._travel, self._dist)
        return self._sum @ (travel[:, None] * self._direction)


def _contracting(muscles: Sequence[Muscle], contractions: Mapping[str, float]) -> list[Muscle]:
    """The muscles with a non-zero contraction; an unknown name is an error that lists the known."""
    known = {m.name for m in muscles}
    unknown = sorted(set(contractions) - known)
    if unknown:
        raise KeyError(f"unknown muscle(s) {unknown}; known: {sorted(known)}")
    return [m for m in muscles if contractions.get(m.name, 0.0) != 0.0]


# -- vertex modes -------------------------------------------------------------------------------

class MuscleModel:
    """Muscles acting on the vertices of one mesh, classic or improved (see module docstring).

    Everything that depends on the rest mesh is computed once here: each muscle's rows, directions
    and travels, the classic mode's sparse matrix (3V x muscles) and, for the improved mode, the
    triangle corners the edge constraints watch. ``movable`` (vertex indices, default all) limits
    which vertices muscles move (the default face: its skin, not the eyeballs and teeth).
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, muscles: Sequence[Muscle],
                 mode: str = "classic", movable: np.ndarray | None = None) -> None:
        if mode not in MODES:
            raise ValueError(f"mode {mode!r}: expected one of {MODES}")
        self.rest = np.asarray(vertices, dtype=float)
        self.muscles = list(muscles)
        self.mode = mode
        mask = np.zeros(len(self.rest), dtype=bool)
        mask[np.arange(len(self.rest)) if movable is None else np.asarray(movable)] = True
        self._fields = {}
        for m in self.muscles:
            rows, direction, travel, dist = _field(m, self.rest)
            keep = mask[rows]
            self._fields[m.name] = (rows[keep], direction[keep], travel[keep], dist[keep])
        self._classic = self._classic_matrix()
        self._edges = EdgeConstraints(self.rest, np.asarray(triangles), mask, self._reached())
        self._watch_cache: dict[tuple[str, ...], np.ndarray] = {}

    def _classic_matrix(self) -> sp.csr_matrix:
        """G (3V x muscles): the classic displacement is G @ contractions, raveled (V, 3)."""
        rows, cols, vals = [], [], []
        for j, (r, direction, travel, _) in enumerate(self._fields.values()):
            rows.append((3 * r[:, None] + np.arange(3)).ravel())
            cols.append(np.full(3 * len(r), j))
            vals.append((travel[:, None] * direction).ravel())
        shape = (3 * len(self.rest), len(self.muscles))
        if not rows:
            return sp.csr_matrix(shape)
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=shape)

    def _reached(self) -> np.ndarray:
        """Vertices some muscle can move."""
        reached = np.zeros(len(self.rest), dtype=bool)
        for rows, *_ in self._fields.values():
            reached[rows] = True
        return reached

    def displace(self, contractions: Mapping[str, float]) -> np.ndarray:
        """Vertex displacements (V, 3) for contractions {muscle name: c}; missing muscles rest."""
        active = _contracting(self.muscles, contractions)
        if self.mode == "classic":
            c = np.array([float(contractions.get(m.name, 0.0)) for m in self.muscles])
            return (self._classic @ c).reshape(-1, 3)
        out = np.zeros_like(self.rest)
        for m in active:
            rows, direction, travel, dist = self._fields[m.name]
            out[rows] += repelled_travel(float(contractions[m.name]) * travel, dist)[:, None] * direction
        if active:
            self._edges.relax(out, self._watched(tuple(m.name for m in active)))
        return out

    def _watched(self, names: tuple[str, ...]) -> np.ndarray:
        """The edge constraints' triangles that muscles ``names`` can squeeze (cached per set)."""
        if names not in self._watch_cache:
            if len(self._watch_cache) >= 64:
                self._watch_cache.clear()
            rows = np.concatenate([self._fields[n][0] for n in names])
            self._watch_cache[names] = self._edges.touching(rows)
        return self._watch_cache[names]


class EdgeConstraints:
    """Compression-only springs from each triangle corner to its opposite edge (improved mode and
    the runtime's fold guard).

    Built once per mesh for the triangles that touch a ``reached`` vertex (bool mask, default all)
    and a ``movable`` one (bool mask), with the vertex -> triangle adjacency (CSR) of those
    triangles; only vertices both reached and movable move (the others have infinite mass), so
    every triangle a fix can change is watched. A corner is *squeezed* when its height above the opposite
    edge, in the plane normal to the triangle's rest normal, is below its floor, ``EDGE_MIN_HEIGHT``
    of its rest height; a triangle folds exactly when a corner crosses its opposite edge (height
    < 0), so a displacement with no squeezed corner folds nothing. ``relax`` (on a displacement)
    and ``guard`` (on positions) fix a field in place, touching only the neighbourhood of the
    squeezed triangles:

    1. **Sweeps**: the squeezed triangles grown by ``EDGE_RINGS`` rings (through shared vertices)
       are the vertices that may move; every corner of the triangles around them is watched. Up to
       ``EDGE_ITERATIONS`` vectorised, over-relaxed Jacobi sweeps: each corner below its floor is
       projected (position-based, inverse-mass weighted: the corner and the two edge ends move along
       the edge's in-plane normal by their share of the gradient) to ``EDGE_TARGET`` times its floor,
       the corrections averaged per vertex and scaled by ``EDGE_OVERRELAX``; they stop as soon as
       no watched corner is squeezed.
    2. **Fallback**, only if some corner is still squeezed (a muscle at several times its normal
       contraction dragging the skin past fixed parts, where the springs ask for the impossible):
       the displacement of every vertex of a squeezed triangle is scaled toward rest by
       ``EDGE_DAMP`` (and the rings around by ``EDGE_DAMP_RINGS``, so the motion saturates
       smoothly instead of leaving a dent), after ``EDGE_DAMP_STEPS`` such steps dropped,
       re-checking only the triangles around the vertices it changed, until no corner is squeezed.
       The rest mesh squeezes no corner and every pass shrinks some non-zero displacement for good,
       so this ends, and the result folds no watched triangle. The price: where it acts (several
       times the normal contraction) the squeezed skin moves less than the muscle asks, e.g. the
       lip corner under the zygomatic major at 10 moves less than at 3 (docs/muscle_experiment.md).

    When nothing is squeezed this costs one vectorised check (``squeezed``) and changes nothing.
    Usable on any displacement field, e.g. the skin after DFFD.
    """

    def __init__(self, rest: np.ndarray, triangles: np.ndarray, movable: np.ndarray | None = None,
                 reached: np.ndarray | None = None) -> None:
        rest = np.asarray(rest, dtype=float)
        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        movable = np.ones(len(rest), bool) if movable is None else np.asarray(movable, bool)
        reached = np.ones(len(rest), bool) if reached is None else np.asarray(reached, bool)
        tri = triangles[reached[triangles].any(axis=1) & movable[triangles].any(axis=1)]
        self.rest = rest
        self.n = len(rest)
        self.triangles = tri
        self._all = np.arange(len(tri))
        normal = np.cross(rest[tri[:, 1]] - rest[tri[:, 0]], rest[tri[:, 2]] - rest[tri[:, 0]])
        self.normal = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
        self._normal_t = np.ascontiguousarray(self.normal.T)
        self._corners = tuple(np.ascontiguousarray(tri[:, k]) for k in range(3))
        area, perp2 = self._area_perp2(rest, self._all)
        height = np.abs(area) / np.sqrt(np.maximum(perp2, 1e-300))
        self.floor = np.ascontiguousarray(EDGE_MIN_HEIGHT * height.T)  # (T, 3): corner k's floor
        self._floor_t = np.ascontiguousarray(self.floor.T)  # (3, T)
        self._floor2 = self._floor_t * self._floor_t
        self.inv_mass = (movable & reached).astype(float)  # only reached vertices move: their triangles are all watched
        flat = tri.ravel()
        order = np.argsort(flat, kind="stable")
        self._vt_ptr = np.searchsorted(flat[order], np.arange(self.n + 1))
        self._vt_tri = order // 3
        self._reference = (np.zeros_like(rest), self._reach(np.zeros_like(rest))[1])  # see _bad
        self._plans: dict[bytes, _SweepPlan] = {}

    # -- geometry ----------------------------------------------------------------------------

    def _edges(self, x: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, ...]:
        """For triangles ``idx`` of positions ``x``: their edges p1 - p0, p2 - p0, p2 - p1 and
        rest normals, coordinates as rows (x, y, z) of contiguous (3, len(idx)) arrays."""
        full = idx is self._all
        xt = np.ascontiguousarray(np.asarray(x, dtype=float).T)
        p0, p1, p2 = (np.take(xt, c if full else c[idx], axis=1) for c in self._corners)
        n = self._normal_t if full else np.take(self._normal_t, idx, axis=1)
        return p1 - p0, p2 - p0, p2 - p1, n

    def _area_perp2(self, x: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For triangles ``idx`` of positions ``x``: twice the area projected along the rest normal
        (negative: folded) and, per corner (rows 0, 1, 2), the squared length of the opposite edge
        in the plane normal to it. The corner's height is the first over the root of the second."""
        return _measured(*self._edges(x, idx))[:2]

    def _squeezed(self, x: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Mask over triangles ``idx``: some corner of positions ``x`` is below its floor."""
        area, perp2 = self._area_perp2(x, idx)
        perp2 *= self._floor2 if idx is self._all else self._floor2[:, idx]
        return (area < 0) | (area * area < perp2.max(axis=0))

    def _reach(self, displacement: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(which triangles have a squeezed corner, how far every corner of each may then move,
        in any directions, before some corner could come below its floor) for ``displacement``
        from rest: the exact check of every triangle, and a sound bound for the next frames.

        For corner v over edge (a, b), in the plane normal to the rest normal (height h, edge
        length L, v's foot at a + t (b - a)), corners moved by at most r turn the edge by an
        angle whose sine is at most 2r / L and move the edge's point at t by at most
        (|1 - t| + |t|) r, so the height stays at least h (1 - 2r / L) - (1 + |1 - t| + |t|) r:
        above the floor f while r <= (h - f) / (2h / L + 1 + |1 - t| + |t|). A squeezed triangle
        may move no distance (its reach is -inf: it is checked whenever asked)."""
        u, v, w, n = self._edges(self.rest + displacement, self._all)
        area, perp2, (wn, vn, un) = _measured(u, v, w, n)
        squeezed = (area < 0) | (area * area < (perp2 * self._floor2).max(axis=0))
        along = np.empty_like(perp2)  # each corner's foot along its edge, times the edge's length squared
        along[0] = un * wn - _dot(u, w)  # corner 0 over p1 -> p2, from p1: (p0 - p1) . w in the plane
        along[1] = _dot(u, v) - un * vn  # corner 1 over p0 -> p2, and corner 2 over p0 -> p1: u . v
        along[2] = along[1]
        length2 = np.maximum(perp2, 1e-300)
        t = along / length2
        length = np.sqrt(length2)
        h = area / length
        reach = ((h - self._floor_t) / (2 * h / length + 1 + np.abs(1 - t) + np.abs(t))).min(axis=0)
        return squeezed, np.where(squeezed | (reach <= 0), -np.inf, SAFE_MARGIN * reach)

    def _bad(self, displacement: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """The triangles of ``idx`` with a squeezed corner under ``displacement`` from rest.

        Exact, and cheap while the field changes little from frame to frame: a reference field
        (rest at first) and each triangle's reach from it (``_reach``) are kept, and only the
        triangles with a corner that drifted farther than that from the reference are checked.
        When over a quarter of them did, every triangle is checked and the field becomes the
        reference."""
        reference, reach = self._reference
        drift = displacement - reference
        drift = np.sqrt(np.einsum("ij,ij->i", drift, drift))
        c0, c1, c2 = self._corners
        if idx is not self._all:
            c0, c1, c2, reach = c0[idx], c1[idx], c2[idx], reach[idx]
        near = idx[np.maximum(np.maximum(drift[c0], drift[c1]), drift[c2]) > reach]
        if 4 * len(near) <= len(idx):
            return near[self._squeezed(self.rest + displacement, near)]
        squeezed, reach = self._reach(displacement)
        self._reference = (displacement.copy(), reach)
        return idx[squeezed[idx]]

    def touching(self, vertices: np.ndarray) -> np.ndarray:
        """Indices of the watched triangles that touch ``vertices`` (ids or a bool mask): what a
        displacement that moves only those vertices can squeeze (``among`` below)."""
        vertices = np.asarray(vertices)
        tris = self._touching(np.flatnonzero(vertices) if vertices.dtype == bool else np.unique(vertices))
        return self._all if len(tris) == len(self._all) else tris  # all: the check's faster path

    def squeezed(self, positions: np.ndarray, among: np.ndarray | None = None) -> bool:
        """Whether some corner of deformed ``positions`` (V, 3) is below its floor (only the watched
        triangles ``among`` are checked when given)."""
        return bool(self._squeezed(positions, self._all if among is None else among).any())

    # -- fixing ------------------------------------------------------------------------------

    def guard(self, positions: np.ndarray, among: np.ndarray | None = None) -> bool:
        """Fix deformed ``positions`` (V, 3) in place if some corner is below its floor; returns
        whether it had to. ``among``: the watched triangles that can be squeezed, when the caller
        knows (``touching`` the vertices it moved); all by default."""
        idx = self._all if among is None else among
        displacement = positions - self.rest
        bad = self._bad(displacement, idx)
        if len(bad) == 0:
            return False
        self._fix(displacement, bad)
        positions[...] = self.rest + displacement
        return True

    def relax(self, displacement: np.ndarray, among: np.ndarray | None = None) -> bool:
        """Fix ``displacement`` (V, 3) from the rest mesh in place (class docstring); returns
        whether some corner was squeezed. ``among`` as for ``guard``."""
        bad = self._bad(displacement, self._all if among is None else among)
        if len(bad) == 0:
            return False
        self._fix(displacement, bad)
        return True

    def _fix(self, displacement: np.ndarray, bad: np.ndarray) -> None:
        left = self._sweep(displacement, self._plan(bad))
        if len(left):
            self._damp(displacement, left)

    def _plan(self, bad: np.ndarray) -> _SweepPlan:
        """The sweeps' neighbourhood of squeezed triangles ``bad``, cached per set (a pose held or
        moving slowly squeezes the same few triangles frame after frame)."""
        key = bad.tobytes()
        plan = self._plans.get(key)
        if plan is None:
            if len(self._plans) >= 64:
                self._plans.clear()
            grown = self._grow(bad, EDGE_RINGS)
            watched = self._grow(grown, 1)
            free = np.zeros(self.n, bool)
            free[self.triangles[grown].ravel()] = True
            plan = self._plans[key] = _SweepPlan(self, watched, free)
        return plan

    def _touching(self, verts: np.ndarray) -> np.ndarray:
        """The watched triangles that touch vertices ``verts`` (sorted, unique)."""
        start, end = self._vt_ptr[verts], self._vt_ptr[verts + 1]
        lens = end - start
        idx = np.repeat(start - np.cumsum(lens) + lens, lens) + np.arange(lens.sum())
        return _unique(self._vt_tri[idx])

    def _grow(self, tris: np.ndarray, rings: int) -> np.ndarray:
        for _ in range(rings):
            tris = self._touching(_unique(self.triangles[tris]))
        return tris

    def _sweep(self, displacement: np.ndarray, plan: _SweepPlan) -> np.ndarray:
        """The sweeps (class docstring, step 1) on the plan's watched triangles, moving only its
        free movable vertices; returns the watched triangles still squeezed after them. The three
        corners of every triangle are one batch (corner k of triangle i is row k * T + i),
        coordinates as rows (x, y, z): a sweep is a few whole-array steps."""
        verts = plan.verts
        x = np.ascontiguousarray((self.rest[verts] + displacement[verts]).T)  # (3, m)
        for sweep in range(EDGE_ITERATIONS + 1):
            low, rows = plan.squeezed(x)
            if len(low) == 0 or sweep == EDGE_ITERATIONS:
                break
            plan.correct(x, low, rows)
        displacement[verts] = x.T - self.rest[verts]
        return plan.watched[_unique(low % len(plan.watched))]

    def _damp(self, displacement: np.ndarray, bad: np.ndarray) -> None:
        """The fallback (class docstring, step 2), from squeezed triangles ``bad``: the displacement
        becomes ``scale * displacement`` with a per-vertex scale that only shrinks (``steps``: how
        often each vertex was a squeezed triangle's)."""
        start = displacement.copy()
        scale = np.ones(self.n)
        steps = np.zeros(self.n, np.int64)
        while len(bad):
            core = _unique(self.triangles[bad])
            steps[core] += 1
            scale[core] = np.where(steps[core] >= EDGE_DAMP_STEPS, 0.0, EDGE_DAMP * scale[core])
            inside = core
            for factor in EDGE_DAMP_RINGS:  # the rings around shrink less: a smooth saturation, not a dent
                grown = _unique(self.triangles[self._touching(inside)])
                ring = _outside(grown, inside)
                scale[ring] *= factor
                inside = grown
            verts = inside
            displacement[verts] = scale[verts, None] * start[verts]
            near = self._touching(verts)
            bad = near[self._squeezed(self.rest + displacement, near)]


def _unique(ids: np.ndarray) -> np.ndarray:
    """``np.unique(ids)`` for integer ids, by one sort: numpy 2's unique hashes first, which costs
    3-6x more on the few hundred vertices or triangles a fix handles at a time."""
    ids = np.sort(ids, axis=None)
    first = np.empty(len(ids), dtype=bool)
    first[:1] = True
    np.not_equal(ids[1:], ids[:-1], out=first[1:])
    return ids[first]


def _outside(ids: np.ndarray, among: np.ndarray) -> np.ndarray:
    """``np.setdiff1d(ids, among, assume_unique=True)`` for sorted unique integer ids, by a binary
    search (the same ids, without building a membership mask)."""
    if len(among) == 0:
        return ids
    at = np.minimum(np.searchsorted(among, ids), len(among) - 1)
    return ids[among[at] != ids]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Column-wise dot products of coordinate-row arrays (3, T)."""
    return np.einsum("ij,ij->j", a, b)


def _measured(u: np.ndarray, v: np.ndarray, w: np.ndarray,
              n: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
    """For triangles with edges u = p1 - p0, v = p2 - p0, w = p2 - p1 and rest normals n (each
    (3, T)): twice the area along n, the squared in-plane lengths of the edges opposite corners
    0, 1, 2 (w, v, u; rows of a (3, T) array) and those edges' components along n."""
    area = (u[1] * v[2] - u[2] * v[1]) * n[0]
    area += (u[2] * v[0] - u[0] * v[2]) * n[1]
    area += (u[0] * v[1] - u[1] * v[0]) * n[2]
    perp2 = np.empty((3, area.shape[0]))
    normal = []
    for k, edge in enumerate((w, v, u)):  # opposite corner 0, 1, 2 (the sign does not matter)
        along = _dot(edge, n)
        perp2[k] = _dot(edge, edge) - along * along
        normal.append(along)
    return area, perp2, tuple(normal)


class _SweepPlan:
    """What ``EdgeConstraints._sweep`` needs around one set of squeezed triangles, in local
    vertex numbering: every watched corner as a row (vertex ``v`` over edge ``a`` -> ``b``, the
    rest normal, the floor) and each vertex's inverse mass (0 where it may not move).

    A sweep on a few hundred rows costs numpy's per-call overhead more than arithmetic, so it is
    written in as few whole-array calls as give the same sums in the same order: the rows' edge,
    corner, in-plane normal and height in one buffer (one fancy index picks the squeezed rows),
    and one ``bincount`` spreading every coordinate's corrections."""

    def __init__(self, edges: EdgeConstraints, watched: np.ndarray, free: np.ndarray) -> None:
        self.watched = watched
        self.verts, local = np.unique(edges.triangles[watched], return_inverse=True)
        local = local.reshape(-1, 3)
        self._ends = np.stack([np.concatenate([local[:, (k + j) % 3] for k in range(3)]) for j in range(3)])  # v, a, b
        normal = np.tile(edges.normal[watched], (3, 1)).T  # (3, rows)
        self._n1, self._n2 = normal[[1, 2, 0]], normal[[2, 0, 1]]  # for the cross product's two terms
        self.floor = edges.floor[watched].T.ravel()
        self.w = edges.inv_mass[self.verts] * free[self.verts]
        m = len(self.verts)
        coordinates = np.array([0, 1, 2, 0, 1])[None, :, None]  # x y z x y: the cross product's rolls are views
        self._gather = coordinates * m + self._ends[[1, 2, 0]][:, None, :]  # (edge start / end / corner, 5, rows)
        self._offsets = np.arange(3)[:, None] * m  # coordinate j of vertex i is bin j * m + i
        self._grad = np.array([[[0.0], [1.0], [-1.0]], [[1.0], [-1.0], [0.0]]])  # grad = [0] * t + [1]
        self._rows = np.empty((14, len(self.floor)))  # edge (5), corner - edge start (5), unit normal (3), height

    def squeezed(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rows of positions ``x`` (3, m) whose corner is below its floor, and for those rows
        (14, n): the edge and corner - edge start (each x y z x y), the edge's unit in-plane
        normal, the corner's height."""
        corners = np.take(x, self._gather)
        rows = self._rows
        np.subtract(corners[1:], corners[0], out=rows[:10].reshape(2, 5, -1))
        edge, rel, across = rows[0:5], rows[5:8], rows[10:13]
        np.subtract(self._n1 * edge[2:5], self._n2 * edge[1:4], out=across)  # normal x edge
        across /= np.maximum(np.sqrt((across * across).sum(axis=0)), 1e-300)
        np.sum(rel * across, axis=0, out=rows[13])
        low = np.flatnonzero(rows[13] < self.floor)
        return low, rows[:, low]

    def correct(self, x: np.ndarray, low: np.ndarray, rows: np.ndarray) -> None:
        """One sweep's projection of the squeezed rows ``low`` (``rows``: as ``squeezed`` gives
        them) into ``x`` in place."""
        e, r, across, height = rows[0:3], rows[5:8], rows[10:13], rows[13]
        t = np.minimum(np.maximum((r * e).sum(axis=0) / np.maximum((e * e).sum(axis=0), 1e-300), 0.0), 1.0)
        ids = self._ends[:, low]  # the corner, then the edge's ends
        grad = self._grad[0] * t + self._grad[1]  # 1, t - 1, -t: d height / d position, along `across`
        wg = self.w[ids] * grad
        denom = (wg * grad).sum(axis=0)
        ok = denom > 0
        step = np.where(ok, (EDGE_TARGET * self.floor[low] - height) / np.where(ok, denom, 1.0), 0.0)
        share = wg * step  # each corner's move along its row's `across`
        m = x.shape[1]
        count = np.maximum(np.bincount(ids.ravel(), weights=(share != 0).ravel(), minlength=m), 1.0)
        moves = np.bincount((ids.ravel() + self._offsets).ravel(), weights=(share * across[:, None]).ravel(),
                            minlength=3 * m).reshape(3, m)
        x += EDGE_OVERRELAX * moves / count


def folded_triangles(rest: np.ndarray, deformed: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Boolean mask of triangles whose normal turned against its rest normal (dot < 0)."""
    def normals(x: np.ndarray) -> np.ndarray:
        return np.cross(x[triangles[:, 1]] - x[triangles[:, 0]], x[triangles[:, 2]] - x[triangles[:, 0]])
    return np.einsum("ij,ij->i", normals(np.asarray(deformed, float)), normals(np.asarray(rest, float))) < 0
