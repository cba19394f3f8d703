"""The sliver guard: the few tiny triangles at the eye corners that a closing upper lid turns
over, found on each face and kept from folding at pose time.

Why they fold: each outer eye corner (3.7, 3.8) stays put, and beside it the upper lid margin
runs almost straight up for about 2 mm in 1 mm triangles (MakeHuman's lid rim wraps from the
skin into the socket there). A closing lid turns that margin down (``autorig``'s ``_lid_share``
fades the turn toward the corner) and DFFD carries the rim's socket side with it, so at a full
blink the skin 1-2 mm above the still corner comes down past it: 9 slivers a side on the default
face past about 645 IRISD (the artist's eyeBlink folds the same triangles, and 40 in all). The
turn cannot fade faster without the blink losing the lid beside the corner, and the socket side
is not a control point.

What it does: the runtime deforms the face once with each of ``PROBED`` at the high end of its
``fap_coding_params.csv`` range; the triangles that fold there, grown by ``RINGS`` rings, are
watched by edge constraints (``puppet.runtime.musclesolver.EdgeConstraints``, the muscle fold
guard's springs). Every frame that brings a watched corner within 5% of its opposite edge, the
constraints push it back, moving only the watched skin vertices that are not feature points (a
FAP still moves its own point by value x FAPU exactly); other frames cost one check of those
few hundred triangles, and a frame whose watched vertices are where the last frame's were (a
held blink) reuses its fix. On the default face a closed lid moves at most 0.94 mm from where DFFD
put it, at the corners only. A limit on the FAP values could not do this: the lid must close.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from puppet.fap.table import N_FAPS, clamp_ranges
from puppet.runtime.lastmade import LastMade
from puppet.runtime.musclesolver import EdgeConstraints, folded_triangles

PROBED = (19, 20)
"""close_t_l_eyelid, close_t_r_eyelid: the FAPs whose range end folds slivers that no limit may
cap (a blink closes at 1024 IRISD)."""
RINGS = 2  # rings of triangles around the folding ones that the guard watches and may move


class SliverGuard:
    """Edge constraints over the triangles that fold in the probe poses (and ``RINGS`` around)."""

    def __init__(self, rest: np.ndarray, triangles: np.ndarray, movable: np.ndarray, probes: list[np.ndarray]) -> None:
        rest = np.asarray(rest, dtype=float)
        tri = np.asarray(triangles, dtype=np.int64)
        folding = np.zeros(len(tri), dtype=bool)
        for positions in probes:
            folding |= folded_triangles(rest, positions, tri)
        reached = _grown(tri, len(rest), folding, RINGS)
        watched = tri[reached[tri].any(axis=1)]
        self.vertices, local = np.unique(watched, return_inverse=True)
        self.constraints = None
        self._last = LastMade()
        if len(self.vertices):
            movable = np.asarray(movable, dtype=bool)[self.vertices]
            self.constraints = EdgeConstraints(rest[self.vertices], local.reshape(-1, 3), movable, reached[self.vertices])

    def __call__(self, out: np.ndarray) -> bool:
        """Fix the deformed positions ``out`` (V, 3) in place where a watched triangle is about
        to fold; returns whether it had to. The fix is a function of the watched vertices'
        positions alone, so a held pose (a held blink) reuses the last frame's."""
        if self.constraints is None:
            return False
        positions = out[self.vertices].astype(float)
        fixed = self._last.get("fixed", positions.tobytes(), lambda: self._fixed(positions))
        if not len(fixed):
            return False
        out[self.vertices] = fixed
        return True

    def _fixed(self, positions: np.ndarray) -> np.ndarray:
        """``positions`` of the watched vertices fixed, or none (0, 3) when nothing was about to fold."""
        return positions if self.constraints.guard(positions) else np.zeros((0, 3))


def _grown(triangles: np.ndarray, n: int, mask: np.ndarray, rings: int) -> np.ndarray:
    """Vertices of the masked triangles and of ``rings`` rings of triangles around them."""
    corners = triangles.ravel()
    incidence = sp.csr_matrix((np.ones(len(corners)), (corners, np.repeat(np.arange(len(triangles)), 3))),
                              shape=(n, len(triangles)))
    vertices = np.zeros(n, dtype=bool)
    vertices[triangles[mask].ravel()] = True
    for _ in range(rings):
        touching = incidence.T @ vertices.astype(float) > 0
        vertices[triangles[touching].ravel()] = True
    return vertices


def sliver_guard(runtime) -> SliverGuard:
    """The guard for a runtime's face and rig, from the runtime's own deformation of each of
    ``PROBED`` at its range end (made before the runtime has a guard). Movable: the DFFD skin
    vertices that are not feature points."""
    high = clamp_ranges()[1]
    probes = []
    for number in PROBED:
        values = np.zeros(N_FAPS)
        values[number - 1] = high[number - 1]
        probes.append(runtime.deform_faps(values).astype(float))
    movable = runtime.dffd_vertices.copy()
    movable[list(runtime.face.feature_vertices.values())] = False
    return SliverGuard(runtime.face.vertices, runtime.face.triangles, movable, probes)
