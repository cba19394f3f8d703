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

A blink is the one motion that needs the fix, so it also gets corrective shapes (as a rigger
would sculpt them): the constraints' fix of each probed lid alone, found where the lid starts to
squeeze the corner and at ``STEPS`` turns from there to its range end, and blended by the lid's
turn (``Corrective``) before the check. A moving blink then finds nothing to fix: its frames
cost 0.39 ms median and 0.64 at most, where the sweeps and their fallback made them 0.9 and 2.8
(``deform_faps``, CPU, both lids swinging 496-1024 IRISD). And the corner follows the lid
smoothly: fixed frame by frame, it jumped 0.9 mm in one 2 IRISD step where the fallback took
over (850 IRISD); blended, no step moves it more than twice the lid's own steps move the skin.
The constraints still check every frame and fix what the shapes do not foresee (a blink with a
squint or a raised cheek).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from puppet.fap.table import N_FAPS, clamp_ranges
from puppet.runtime.fapengine import LID_FAPS
from puppet.runtime.lastmade import LastMade
from puppet.runtime.musclesolver import EdgeConstraints, folded_triangles

PROBED = (19, 20)
"""close_t_l_eyelid, close_t_r_eyelid: the FAPs whose range end folds slivers that no limit may
cap (a blink closes at 1024 IRISD)."""
RINGS = 2  # rings of triangles around the folding ones that the guard watches and may move
STEPS = 8  # corrective shapes per probed lid, from where it starts to squeeze to its range end
ONSET_TOLERANCE = 1.0  # FAP units: how closely the lid value where the squeeze starts is found


class Corrective:
    """The guard's fix of the watched vertices as one lid turns alone: fixes (K, n, 3) at turns
    ``angles`` (K, radians about the lid's axis, rising toward closed; the first fix is nothing,
    where the lid starts to squeeze), blended linearly between them, nothing before the first
    and the last beyond the end."""

    def __init__(self, part: str, axis: np.ndarray, angles: np.ndarray, fixes: np.ndarray) -> None:
        self.part = part
        self.axis = np.asarray(axis, dtype=float)
        self.sign = 1.0 if angles[-1] >= angles[0] else -1.0
        self.angles = self.sign * np.asarray(angles, dtype=float)
        self.fixes = np.asarray(fixes, dtype=float)

    def at(self, motion: np.ndarray) -> np.ndarray | None:
        """The fix for the lid's rigid ``motion`` (3 x 4), or None where there is nothing to add."""
        angle = self.sign * turn_about(motion, self.axis)
        if angle <= self.angles[0]:
            return None
        k = min(int(np.searchsorted(self.angles, angle)), len(self.angles) - 1)
        t = min((angle - self.angles[k - 1]) / (self.angles[k] - self.angles[k - 1]), 1.0)
        return (1.0 - t) * self.fixes[k - 1] + t * self.fixes[k]


def turn_about(motion: np.ndarray, axis: np.ndarray) -> float:
    """The signed angle (radians) of a rigid ``motion``'s rotation about unit ``axis``."""
    r = motion[:, :3]
    sine = 0.5 * float(axis @ np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]))
    return float(np.arctan2(sine, 0.5 * (np.trace(r) - 1.0)))


class SliverGuard:
    """Edge constraints over the triangles that fold in the probe poses (and ``RINGS`` around)."""

    def __init__(self, rest: np.ndarray, triangles: np.ndarray, movable: np.ndarray, probes: list[np.ndarray]) -> None:
        self.shapes: list[Corrective] = []  # added by ``sliver_guard`` once the guard exists
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

    def __call__(self, out: np.ndarray, rigid: dict[str, np.ndarray]) -> bool:
        """Add the corrective shapes for the lids' turns in ``rigid`` to the deformed positions
        ``out`` (V, 3), then fix them in place where a watched triangle is still about to fold;
        returns whether it had to. The fix is a function of the watched vertices' positions
        alone, so a held pose (a held blink) reuses the last frame's."""
        if self.constraints is None:
            return False
        positions = out[self.vertices].astype(float)
        shaped = self._shape(positions, rigid)
        fixed = self._last.get("fixed", positions.tobytes(), lambda: self._fixed(positions.copy()))
        if len(fixed) or shaped:
            out[self.vertices] = fixed if len(fixed) else positions
        return bool(len(fixed))

    def _shape(self, positions: np.ndarray, rigid: dict[str, np.ndarray]) -> bool:
        """Add the corrective shapes to the watched ``positions`` in place; whether any added."""
        shaped = False
        for shape in self.shapes:
            motion = rigid.get(shape.part)
            fix = None if motion is None else shape.at(motion)
            if fix is not None:
                positions += fix
                shaped = True
        return shaped

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
    ``PROBED`` at its range end (made before the runtime has a guard), with its corrective
    shapes. Movable: the DFFD skin vertices that are not feature points."""
    high = clamp_ranges()[1]
    probes = [_lid_pose(runtime, number, high[number - 1])[0] for number in PROBED]
    movable = runtime.dffd_vertices.copy()
    movable[list(runtime.face.feature_vertices.values())] = False
    guard = SliverGuard(runtime.face.vertices, runtime.face.triangles, movable, probes)
    if guard.constraints is not None:
        shapes = [_corrective(runtime, guard, number, high[number - 1]) for number in PROBED
                  if LID_FAPS[number][0] in runtime.rig.rigid_parts]
        guard.shapes = [shape for shape in shapes if shape is not None]
    return guard


def _corrective(runtime, guard: SliverGuard, number: int, high: float) -> Corrective | None:
    """The corrective shape of lid FAP ``number``: the guard's fix at ``STEPS`` values from where
    the lid alone starts to squeeze a watched corner to ``high``, by the lid's turn; None if it
    squeezes none (on a face where only the other lid's corners fold)."""
    part = LID_FAPS[number][0]
    axis = runtime.rig.rigid_parts[part].axis
    onset = _onset(runtime, guard, number, high)
    if onset >= high:
        return None
    values = np.linspace(onset, high, STEPS + 1)
    angles, fixes = [], []
    for value in values:
        positions, motion = _lid_pose(runtime, number, value)
        watched = positions[guard.vertices]
        fixed = watched.copy()
        guard.constraints.guard(fixed)
        angles.append(turn_about(motion, axis))
        fixes.append(fixed - watched)
    angles = np.array(angles)  # the first fix is nothing: at the onset no watched corner is squeezed
    turning = np.concatenate([[True], np.abs(angles[1:] - angles[0]) > np.abs(angles[:-1] - angles[0])])
    if turning.sum() < 2:  # the lid does not turn past its onset
        return None
    return Corrective(part, axis, angles[turning], np.array(fixes)[turning])  # a lid past meeting turns no more


def _onset(runtime, guard: SliverGuard, number: int, high: float) -> float:
    """The largest value of lid FAP ``number`` alone (to ``ONSET_TOLERANCE``) at which no watched
    corner is squeezed: the guard's first work is just above it."""
    low = 0.0
    if not guard.constraints.squeezed(_lid_pose(runtime, number, high)[0][guard.vertices]):
        return high
    while high - low > ONSET_TOLERANCE:
        middle = 0.5 * (low + high)
        squeezed = guard.constraints.squeezed(_lid_pose(runtime, number, middle)[0][guard.vertices])
        low, high = (low, middle) if squeezed else (middle, high)
    return low


def _lid_pose(runtime, number: int, value: float) -> tuple[np.ndarray, np.ndarray | None]:
    """(the face's positions, the lid's rigid motion, None without that lid) with FAP ``number``
    at ``value`` alone, as the runtime deforms it without a sliver guard."""
    values = np.zeros(N_FAPS)
    values[number - 1] = value
    rigid = runtime.fap_controls(values)[1]
    return runtime.deform_faps(values).astype(float), rigid.get(LID_FAPS[number][0])
