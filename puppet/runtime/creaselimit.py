"""The cheeks' crease limit: ``lift_cheek`` lowered at pose time as far as the skin under the eye
needs, whatever else the frame moves.

Why: lift_l/r_cheek's calibrated motion lifts the cheekbone's point (5.3, 5.4) faster than the
skin around it, and in a smile the skin under the eye bends along a line, a bright crease: the
ARKit route's live smile (mouthSmile and cheekSquint at full, both sides) bent an edge there by
122 degrees, cheekSquint alone by 48; the artist's smile bends them 8. A limit on lift_cheek
alone cannot help, since how far it creases depends on the rest of the frame (alone it creases
from about 130 ENS, in a smile from about 100), and a crease limit on every FAP, as the fold
limit is, would cap nearly all of them on this face (``docs/guide/contributors/realism.md``).

What it does (``CreaseLimit.limit``, called by ``FapEngine.shown``): for each limited FAP whose
value is not 0, the bend of the skin's interior edges within ``NEAR`` face widths of its feature
point (``puppet.runtime.creases``), from the frame's translations spread by DFFD onto those few
vertices (exact for the FAPs' own and calibrated motions; the rigid parts' carried points, which
do not reach the cheekbones, are left out). Where the largest bend passes ``BOUND`` and more than
the frame would bend without the FAP, the FAP is lowered (``STEPS`` halvings) until it does not;
what a file says is never changed. About 30 microseconds a frame when a cheek FAP is not 0.
"""

from __future__ import annotations

import functools

import numpy as np

from puppet.runtime.creases import Hinges, near_edges

LIMITED = {41: "5.3", 42: "5.4"}
"""lift_l_cheek, lift_r_cheek: the FAP and the feature point around which it creases the skin."""
NEAR = 0.08
"""Face widths (the skin's extent in x) around the point within which edges are watched."""
BOUND = np.radians(20.0)
"""The most a watched edge may bend beyond its rest angle through the FAP (the artist's smile
bends them 8 degrees; joy without lift_cheek 13)."""
STEPS = 8
"""Halvings of the share of its value a lowered FAP keeps."""


class _Watch:
    """The watched edges over the few vertices their two triangles touch: each edge's ends and its
    triangles' corners (coordinates as rows, so the bends are a few whole-array steps on a few
    dozen columns), the rest angles, which limited FAP each edge is watched for (``side``: its
    index in ``CreaseLimit.numbers``), and the vertices' displacement per unit of each FAP (3n, 68)."""

    def __init__(self, hinges: Hinges, triangles: np.ndarray, rest: np.ndarray, response: np.ndarray,
                 side: np.ndarray) -> None:
        self.ends = hinges.edges.T
        self.corners = np.r_[triangles[hinges.left], triangles[hinges.right]].T  # (3, 2E): the left triangles, then the right
        self.count = len(hinges.edges)
        self.rest = np.ascontiguousarray(rest.T)
        self.response = response
        self.side = side
        self.angles = hinges.dihedral(rest, triangles)

    def bends(self, displacement: np.ndarray) -> np.ndarray:
        """Each watched edge's bend (radians, either way) for the vertices' ``displacement`` (3n,)."""
        x = self.rest + displacement.reshape(-1, 3).T
        p0, p1, p2 = (x[:, c] for c in self.corners)
        u, w = p1 - p0, p2 - p0
        n = np.array([u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]])
        n1, n2 = n[:, : self.count], n[:, self.count:]
        axis = x[:, self.ends[1]] - x[:, self.ends[0]]
        across = np.array([n1[1] * n2[2] - n1[2] * n2[1], n1[2] * n2[0] - n1[0] * n2[2], n1[0] * n2[1] - n1[1] * n2[0]])
        sine = (across * axis).sum(axis=0) / np.sqrt((axis * axis).sum(axis=0))
        angle = np.arctan2(sine, (n1 * n2).sum(axis=0))
        return np.abs(np.pi - np.remainder(np.pi - (angle - self.angles), 2 * np.pi))


class CreaseLimit:
    """The crease limit of one runtime's face (module docstring)."""

    def __init__(self, engine) -> None:
        self.engine = engine
        face = engine.face
        self.numbers = [n for n, point in LIMITED.items() if "skin" in face.parts and point in face.feature_vertices
                        and point in engine._index and engine._moving[n - 1]]

    def limit(self, v: np.ndarray) -> None:
        """Lower the limited FAPs of the shown values ``v`` (68,) in place where they crease."""
        lifted = [k for k, number in enumerate(self.numbers) if v[number - 1] != 0]
        if not lifted:
            return
        watch = self._watch
        full = watch.response @ v
        bends = watch.bends(full)
        for k in lifted:
            mine = watch.side == k
            if bends[mine].max(initial=0.0) > BOUND:
                full = self._lowered(watch, mine, self.numbers[k] - 1, full, v)

    def _lowered(self, watch: _Watch, mine: np.ndarray, column: int, full: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Lower ``v[column]`` until the edges ``mine`` bend no more than ``BOUND`` or than they bend
        without it; the watched vertices' displacement ``full`` then."""
        own = watch.response[:, column] * v[column]

        def bend(share: float) -> float:
            return float(watch.bends(full - (1.0 - share) * own)[mine].max())

        allowed = max(BOUND, bend(0.0))
        if bend(1.0) <= allowed:
            return full
        good, bad = 0.0, 1.0
        for _ in range(STEPS):
            share = (good + bad) / 2
            good, bad = (share, bad) if bend(share) <= allowed else (good, share)
        v[column] *= good
        return full - (1.0 - good) * own

    @functools.cached_property
    def _watch(self) -> _Watch:
        """The watch of every limited FAP's edges, made on first use (a runtime that never lifts a
        cheek never pays)."""
        engine = self.engine
        face, runtime = engine.face, engine.runtime
        rest = np.asarray(face.vertices, dtype=float)
        triangles = np.asarray(face.triangles, dtype=np.int64)
        hinges = Hinges.of(triangles)
        side = np.full(len(hinges.edges), -1)
        for k, number in enumerate(self.numbers):
            side[near_edges(face, hinges, LIMITED[number], NEAR) & (side < 0)] = k
        B = runtime.B if runtime.mode == "precomputed" else runtime._folded()
        return _watched(hinges, side, triangles, rest, B, engine._translations.reshape(len(runtime.control_points), 3, -1))


def _watched(hinges: Hinges, side: np.ndarray, triangles: np.ndarray, rest: np.ndarray, B, moves: np.ndarray) -> _Watch:
    """The watch of the edges with a ``side`` (-1: not watched): their two triangles' vertices
    renumbered, and those vertices' response to each FAP, DFFD's rows ``B`` over the active points'
    ``moves`` (K, 3, 68)."""
    near = side >= 0
    left, right = hinges.left[near], hinges.right[near]
    vertices, local = np.unique(triangles[np.r_[left, right]], return_inverse=True)
    count = int(near.sum())
    rows = np.asarray(B[vertices][:, : moves.shape[0]].todense(), dtype=float)
    response = np.einsum("vk,kaf->vaf", rows, moves).reshape(-1, moves.shape[2])
    local_hinges = Hinges(np.searchsorted(vertices, hinges.edges[near]), np.arange(count), np.arange(count, 2 * count))
    return _Watch(local_hinges, local.reshape(-1, 3), rest[vertices], response, side[near])
