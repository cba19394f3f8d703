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
the frame would bend without the FAP, the FAP is lowered until it does not;
what a file says is never changed. Its price (``FapEngine.shown``, 2 idle cores): 0.11 ms a frame with a
cheek lifted (joy: 0.04 -> 0.15 ms), 0.76 ms a frame where it lowers both (the live smile held: 0.05 ->
0.81 ms), nothing where no cheek moves.
"""

from __future__ import annotations

import functools

import numpy as np

from puppet.runtime.creases import Hinges, near_edges, wrapped

LIMITED = {41: "5.3", 42: "5.4"}
"""lift_l_cheek, lift_r_cheek: the FAP and the feature point around which it creases the skin."""
NEAR = 0.08
"""Face widths (the skin's extent in x) around the point within which edges are watched."""
BOUND = np.radians(20.0)
"""The most a watched edge may bend beyond its rest angle through the FAP (the artist's smile
bends them 8 degrees; joy without lift_cheek 13)."""
SHARES = 17
"""Shares of its value a lowered FAP is tried at in one go, twice (coarse, then fine): the share it
keeps is found to 1/256 (1 ENS of lift_cheek's 209 reach on the default face)."""


class _Watch:
    """One limited FAP's watched edges over the few vertices their two triangles touch: each edge's
    ends and its triangles' corners (coordinates as rows, so the bends are a few whole-array steps on
    a few dozen columns), the rest angles, and the vertices' displacement per unit of each FAP (3n, 68)."""

    def __init__(self, hinges: Hinges, triangles: np.ndarray, rest: np.ndarray, response: np.ndarray) -> None:
        self.ends = hinges.edges.T
        self.corners = np.r_[triangles[hinges.left], triangles[hinges.right]].T  # (3, 2E): the left triangles, then the right
        self.count = len(hinges.edges)
        self.rest = np.ascontiguousarray(rest.T)
        self.response = response
        self.angles = hinges.dihedral(rest, triangles)

    def bends(self, displacements: np.ndarray) -> np.ndarray:
        """Each watched edge's bend (S, E; radians, either way) for each of the vertices'
        ``displacements`` (S, 3n), in one go."""
        x = self.rest + displacements.reshape(len(displacements), -1, 3).transpose(0, 2, 1)
        p0, p1, p2 = (x[:, :, c] for c in self.corners)
        u, w = p1 - p0, p2 - p0
        n = _cross(u, w)
        n1, n2 = n[:, :, : self.count], n[:, :, self.count:]
        axis = x[:, :, self.ends[1]] - x[:, :, self.ends[0]]
        sine = (_cross(n1, n2) * axis).sum(axis=1) / np.sqrt((axis * axis).sum(axis=1))
        angle = np.arctan2(sine, (n1 * n2).sum(axis=1))
        return np.abs(wrapped(angle - self.angles))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of coordinate-row batches (S, 3, m)."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


class CreaseLimit:
    """The crease limit of one runtime's face (module docstring)."""

    def __init__(self, engine) -> None:
        self.engine = engine
        face = engine.face
        self.numbers = [n for n, point in LIMITED.items() if "skin" in face.parts and point in face.feature_vertices
                        and point in engine._index and engine._moving[n - 1]]

    def limit(self, v: np.ndarray) -> None:
        """Lower the limited FAPs of the shown values ``v`` (68,) in place where they crease."""
        for k, number in enumerate(self.numbers):
            if v[number - 1] == 0:
                continue
            watch = self._watches[k]
            full = watch.response @ v
            if watch.count and watch.bends(full[None]).max() > BOUND:  # a mesh may have no skin edge near the point
                v[number - 1] *= _kept(watch, full, watch.response[:, number - 1] * v[number - 1])

    @functools.cached_property
    def _watches(self) -> list[_Watch]:
        """Each limited FAP's watch, made on first use (a runtime that never lifts a cheek never pays)."""
        engine = self.engine
        face, runtime = engine.face, engine.runtime
        rest = np.asarray(face.vertices, dtype=float)
        triangles = np.asarray(face.triangles, dtype=np.int64)
        hinges = Hinges.of(triangles)
        B = runtime.B if runtime.mode == "precomputed" else runtime._folded()
        moves = engine._translations.reshape(len(runtime.control_points), 3, -1)
        return [_watched(hinges, near_edges(face, hinges, LIMITED[number], NEAR), triangles, rest, B, moves)
                for number in self.numbers]


def _kept(watch: _Watch, full: np.ndarray, own: np.ndarray) -> float:
    """The share of its value a FAP keeps whose part of the watched vertices' displacement ``full``
    is ``own``: the largest on a grid of ``SHARES`` from 0 to 1, refined once on as fine a grid up
    to the next, that bends the edges no more than ``BOUND`` or than they bend without it."""
    def bends(shares: np.ndarray) -> np.ndarray:
        return watch.bends(full - np.outer(1.0 - shares, own)).max(axis=1)

    coarse = np.linspace(0.0, 1.0, SHARES)
    bend = bends(coarse)
    allowed = max(BOUND, bend[0])
    if bend[-1] <= allowed:
        return 1.0
    first = int(np.argmax(bend > allowed))  # the first share that bends past it (not 0: that one is allowed)
    fine = np.linspace(coarse[first - 1], coarse[first], SHARES)
    return float(fine[int(np.argmax(bends(fine) > allowed)) - 1])


def _watched(hinges: Hinges, near: np.ndarray, triangles: np.ndarray, rest: np.ndarray, B, moves: np.ndarray) -> _Watch:
    """The watch of the edges ``near`` (a mask over ``hinges``): their two triangles' vertices
    renumbered, and those vertices' response to each FAP, DFFD's rows ``B`` over the active points'
    ``moves`` (K, 3, 68)."""
    left, right = hinges.left[near], hinges.right[near]
    vertices, local = np.unique(triangles[np.r_[left, right]], return_inverse=True)
    count = int(near.sum())
    rows = np.asarray(B[vertices][:, : moves.shape[0]].todense(), dtype=float)
    response = np.einsum("vk,kaf->vaf", rows, moves).reshape(-1, moves.shape[2])
    local_hinges = Hinges(np.searchsorted(vertices, hinges.edges[near]), np.arange(count), np.arange(count, 2 * count))
    return _Watch(local_hinges, local.reshape(-1, 3), rest[vertices], response)
