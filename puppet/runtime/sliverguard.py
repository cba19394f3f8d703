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
held blink) reuses its fix. On the default face a closed lid moves at most 0.97 mm from where DFFD
put it, at the corners only. A limit on the FAP values could not do this: the lid must close.

A blink is the one motion that needs the fix, so it also gets corrective shapes (as a rigger
would sculpt them): the constraints' fix of each probed lid alone, found where the lid starts to
squeeze the corner and at ``STEPS`` turns from there to its range end, and blended by the lid's
turn (``Corrective``) before the check. A moving blink then finds nothing to fix: its frames
cost 0.39 ms median and 0.64 at most, where the sweeps and their fallback made them 0.9 and 2.8
(``deform_faps``, CPU, both lids swinging 496-1024 IRISD). And the corner follows the lid
smoothly: fixed frame by frame, it jumped 0.9 mm in one 2 IRISD step where the fallback took
over (850 IRISD); blended, no step moves it more than twice the lid's own steps move the skin.
A frown with a blink squeezes the outer corner sooner and harder (brows lowered push the skin
above the lid down onto it), so each lid's shapes are sampled with the brows on its side lowered
as well (``FROWNS``, at ``FROWN_DEPTHS`` of the way to the face's reach, each from where the lid
starts to squeeze under that frown) and blended by how far the brows are lowered (``Frown``: read
from the control points' displacements, blind to the lids' own FAPs). Sampled for the lid alone,
a frown with a blink was left to the constraints: the shipped slider box needed their fix in 20%
of its frames (1.1 ms more each; 3.1% after; 19% again since its blink slider closes the eye
with the lower lid's share, which the shapes do not foresee: sampled with it too, they closed
the eye less well than the constraints' own fix and stepped 7 times the median, against 1.3),
and under a full frown the corner jumped back and forth by 2.5 mm in single 2 IRISD steps of
the blink (984, 1004, 1022 IRISD), 86 times the median step (the biggest step is now 6 times the
median, at the lid's very end, as a slide over 8 IRISD; ``docs/frown_blink_corners.png``). The
other side's brows squeeze a corner a little too (the artists' brow motions reach across the
face), which the shapes do not foresee; nor a blink with a squint or a raised cheek: the
constraints still check every frame and fix what is left.

The same constraints watch the rig's ``guarded`` triangles (``puppet.face.rig``): on a face rigged
by transfer, FAPs that each fold nothing within their limits fold a few triangles together in the
expressions and visemes (the ICT head: 85 over the 21 poses, at the lip corners, the cheeks and
the eye corners), and ``foldlimits`` lists them there. Watched, they fold in none (per-frame
cost on ICT through the 21 poses ramped: 1.1 -> 1.35 ms median). On the default face they are
the hidden slivers inside the lip corners that joy turns over, its corners raised 90% of the
artist's smile (0.24 -> 0.39-0.43 ms median per frame through the same poses,
``tools/bench/bench_expressions.py``: the mouth's watched triangles are checked whenever it
moves). A fix that would show more triangles turned over than it found, counted on every
triangle it can move, is not shown: where a pose presses the lips hard against a watched corner
the springs cannot hold it, and their fallback drew the skin toward rest by millimetres.
"""

from __future__ import annotations

import math

import numpy as np

from puppet.face.rigid import IDENTITY
from puppet.fap.table import clamp_ranges
from puppet.runtime.lastmade import LastMade
from puppet.runtime.lids import LID_FAPS
from puppet.runtime.musclesolver import EdgeConstraints, folded_triangles
from puppet.runtime.skinsmoothing import grown, neighbours

PROBED = (19, 20)
"""close_t_l_eyelid, close_t_r_eyelid: the FAPs whose range end folds slivers that no limit may
cap (a blink closes at 1024 IRISD)."""
RINGS = 2  # rings of triangles around the folding ones that the guard watches and may move
STEPS = 8  # corrective shapes per probed lid, from where it starts to squeeze to its range end
ONSET_TOLERANCE = 1.0  # FAP units: how closely the lid value where the squeeze starts is found
ONSET_SCAN = 16  # lid values tried from open to the range end before the squeeze's start is bisected
FROWNS = {19: (31, 33, 35), 20: (32, 34, 36)}
"""The brow FAPs (raise_l/r_i/m/o_eyebrow) on each probed lid's side: lowered, they push the skin
above the lid onto its outer corner."""
FROWN_DEPTHS = (0.0, 0.5, 1.0)  # how far the brows are lowered in the samples: none to the face's reach
BLEND_FLOOR = 1e-6  # a frown depth's share of the blend below which its shape is not looked up


class Frown:
    """How far the brows on one lid's side are lowered, read from the active control points'
    displacements: their sum over ``rows`` weighted by ``weights`` (r, 3), which gives 1 at the
    full frown (the face's reach) and 0 for any motion of the lids (``_frown``), clipped to 0-1."""

    def __init__(self, rows: np.ndarray, weights: np.ndarray) -> None:
        self.rows = np.asarray(rows, dtype=np.int64)
        self.weights = np.asarray(weights, dtype=float)
        self._flat = (3 * self.rows[:, None] + np.arange(3)).ravel()  # the rows' entries in a raveled (K, 3)
        self._flat_weights = self.weights.ravel()

    def depth(self, displacements: np.ndarray) -> float:
        """0 to 1 for the active control points' ``displacements`` (K, 3)."""
        along = float(np.asarray(displacements).ravel().take(self._flat) @ self._flat_weights)  # the rows, then float64
        return min(max(along, 0.0), 1.0)


class TurnShape:
    """The guard's fix of the watched vertices as one lid turns: fixes (K, n, 3) at turns ``angles``
    (K, radians about the lid's axis, rising toward closed; the first is where the lid starts to
    squeeze, whose fix is nothing, or the lid open where something else squeezes the corner
    already), blended linearly between them, the first before it and the last beyond the end."""

    def __init__(self, angles: np.ndarray, fixes: np.ndarray) -> None:
        self.sign = 1.0 if angles[-1] >= angles[0] else -1.0
        self.angles = self.sign * np.asarray(angles, dtype=float)
        self.fixes = np.asarray(fixes, dtype=float)
        self._before = self.fixes[0] if self.fixes[0].any() else None

    def at(self, angle: float) -> np.ndarray | None:
        """The fix for the lid turned by ``angle`` (radians about its axis), or None where there is
        nothing to add."""
        angle *= self.sign
        if angle <= self.angles[0]:
            return self._before
        k = min(int(np.searchsorted(self.angles, angle)), len(self.angles) - 1)
        t = min((angle - self.angles[k - 1]) / (self.angles[k] - self.angles[k - 1]), 1.0)
        return (1.0 - t) * self.fixes[k - 1] + t * self.fixes[k]


class Corrective:
    """A lid's corrective shapes: one ``TurnShape`` for each frown depth in ``depths`` (rising from
    0, the lid alone; None where the lid squeezes no corner under that frown), by the lid's turn
    about ``axis``, blended linearly by how far ``frown`` finds the brows lowered (the deepest
    beyond the last depth); a shape before its lid's onset adds nothing to the blend."""

    def __init__(self, part: str, axis: np.ndarray, turns: list[TurnShape | None],
                 depths: np.ndarray = (0.0,), frown: Frown | None = None) -> None:
        self.part = part
        self.axis = np.asarray(axis, dtype=float)
        self.turns = turns
        self.depths = np.asarray(depths, dtype=float)
        self.frown = frown

    def at(self, motion: np.ndarray, displacements: np.ndarray | None = None) -> np.ndarray | None:
        """The fix for the lid's rigid ``motion`` (3 x 4) under the frown of the active control
        points' ``displacements`` (K, 3; None: no frown), or None where there is nothing to add."""
        angle = turn_about(motion, self.axis)
        if len(self.turns) == 1 or self.frown is None or displacements is None:
            return self._at(0, angle)
        depth = self.frown.depth(displacements)
        i = min(max(int(np.searchsorted(self.depths, depth)), 1), len(self.depths) - 1)
        u = min((depth - self.depths[i - 1]) / (self.depths[i] - self.depths[i - 1]), 1.0)
        if u < BLEND_FLOOR or u > 1.0 - BLEND_FLOOR:  # one shape's worth: the other adds under a millionth
            return self._at(i - 1 if u < BLEND_FLOOR else i, angle)
        shallow, deep = self._at(i - 1, angle), self._at(i, angle)
        if shallow is None and deep is None:
            return None
        return (1.0 - u) * (0.0 if shallow is None else shallow) + u * (0.0 if deep is None else deep)

    def _at(self, k: int, angle: float) -> np.ndarray | None:
        """Depth ``k``'s fix for the lid turned by ``angle``, None where it has none."""
        turn = self.turns[k]
        return None if turn is None else turn.at(angle)


def turn_about(motion: np.ndarray, axis: np.ndarray) -> float:
    """The signed angle (radians) of a rigid ``motion``'s rotation about unit ``axis``."""
    (r00, r01, r02, _), (r10, r11, r12, _), (r20, r21, r22, _) = np.asarray(motion, dtype=float).tolist()
    x, y, z = np.asarray(axis, dtype=float).tolist()
    sine = 0.5 * (x * (r21 - r12) + y * (r02 - r20) + z * (r10 - r01))
    return math.atan2(sine, 0.5 * (r00 + r11 + r22 - 1.0))


class SliverGuard:
    """Edge constraints over the triangles that fold in the probe poses (and ``RINGS`` around)."""

    def __init__(self, rest: np.ndarray, triangles: np.ndarray, movable: np.ndarray, probes: list[np.ndarray],
                 guarded: np.ndarray | None = None) -> None:
        self.shapes: list[Corrective] = []  # added by ``sliver_guard`` once the guard exists
        rest = np.asarray(rest, dtype=float)
        tri = np.asarray(triangles, dtype=np.int64)
        folding = np.zeros(len(tri), dtype=bool)
        for positions in probes:
            folding |= folded_triangles(rest, positions, tri)
        if guarded is not None and len(guarded):
            listed = np.zeros(len(rest), dtype=bool)
            listed[guarded] = True
            folding |= listed[tri].all(axis=1)
        corners = np.zeros(len(rest), dtype=bool)
        corners[tri[folding].ravel()] = True
        reached = grown(corners, neighbours(tri, len(rest)), RINGS)
        watched = tri[reached[tri].any(axis=1)]
        self.vertices, local = np.unique(watched, return_inverse=True)
        around = tri[np.isin(tri, self.vertices).any(axis=1)]  # every triangle a fix can turn over
        self._near, near_local = np.unique(around, return_inverse=True)
        self._around, self._rest_near = near_local.reshape(-1, 3), rest[self._near]
        self._inside = np.searchsorted(self._near, self.vertices)  # the watched vertices among the near ones
        self.constraints = None
        self._last = LastMade()
        if len(self.vertices):
            movable = np.asarray(movable, dtype=bool)[self.vertices]
            self.constraints = EdgeConstraints(rest[self.vertices], local.reshape(-1, 3), movable, reached[self.vertices])

    def __call__(self, out: np.ndarray, rigid: dict[str, np.ndarray],
                 displacements: np.ndarray | None = None) -> bool:
        """Add the corrective shapes for the lids' turns in ``rigid`` and the frown in the active
        control points' ``displacements`` (K, 3) to the deformed positions ``out`` (V, 3), then fix
        them in place where a watched triangle is still about to fold; returns whether it had to.
        The fix is a function of the watched vertices' positions alone, so a held pose (a held
        blink) reuses the last frame's."""
        if self.constraints is None:
            return False
        near = out[self._near].astype(float)
        positions = near[self._inside]
        shaped = self._shape(positions, rigid, displacements)
        near[self._inside] = positions
        fixed = self._last.get("fixed", near.tobytes(), lambda: self._fixed(near))
        if len(fixed) or shaped:
            out[self.vertices] = (fixed if len(fixed) else near)[self._inside]
        return bool(len(fixed))

    def _shape(self, positions: np.ndarray, rigid: dict[str, np.ndarray],
               displacements: np.ndarray | None) -> bool:
        """Add the corrective shapes to the watched ``positions`` in place; whether any added."""
        shaped = False
        for shape in self.shapes:
            motion = rigid.get(shape.part)
            fix = None if motion is None else shape.at(motion, displacements)
            if fix is not None:
                positions += fix
                shaped = True
        return shaped

    def _fixed(self, near: np.ndarray) -> np.ndarray:
        """``near`` (the positions of the watched vertices and the ring around them, left as they are) fixed,
        as a new array, or none (0, 3) when nothing was about to fold or the fix would show more folded
        triangles than it found: where a pose squeezes watched triangles that the springs cannot hold (the
        lips pursed against a lip corner whose smile slivers are watched), their fallback draws the skin
        toward rest by millimetres and turns the triangles around over instead."""
        positions = near[self._inside]
        if not self.constraints.guard(positions):
            return np.zeros((0, 3))
        fixed = near.copy()
        fixed[self._inside] = positions
        return fixed if self._folds(fixed) <= self._folds(near) else np.zeros((0, 3))

    def _folds(self, near: np.ndarray) -> int:
        """How many of the triangles around the watched vertices ``near`` turns over."""
        return int(folded_triangles(self._rest_near, near, self._around).sum())


def sliver_guard(runtime) -> SliverGuard:
    """The guard for a runtime's face and rig, from the runtime's own deformation of each of
    ``PROBED`` at its range end (made before the runtime has a guard) and the rig's ``guarded``
    triangles, with its corrective shapes. Movable: the DFFD skin vertices that are not feature
    points. The probes move a lid and its brows alone, so they deform ``Runtime.for_few_inputs``."""
    high = clamp_ranges()[1]
    lids = runtime.for_few_inputs()
    probes = [_lid_pose(lids, number, high[number - 1])[0] for number in PROBED]
    movable = runtime.dffd_vertices.copy()
    movable[list(runtime.face.feature_vertices.values())] = False
    guard = SliverGuard(runtime.face.vertices, runtime.face.triangles, movable, probes, runtime.rig.guarded)
    if guard.constraints is not None:
        shapes = [_corrective(lids, guard, number, high[number - 1]) for number in PROBED
                  if LID_FAPS[number][0] in runtime.rig.rigid_parts]
        guard.shapes = [shape for shape in shapes if shape is not None]
    return guard


def _corrective(runtime, guard: SliverGuard, number: int, high: float) -> Corrective | None:
    """The corrective shapes of lid FAP ``number`` under each of ``FROWN_DEPTHS``: the guard's fix
    at ``STEPS`` values from where the lid starts to squeeze a watched corner under that frown to
    ``high``; None if it squeezes none under any (on a face where only the other lid's corners
    fold)."""
    part = LID_FAPS[number][0]
    axis = runtime.rig.rigid_parts[part].axis
    brows = _brows_lowered(runtime, number)
    frown = _frown(runtime, guard, brows)
    depths = np.array(FROWN_DEPTHS if frown is not None else FROWN_DEPTHS[:1])
    turns = [_turn_shape(runtime, guard, number, high, axis, {brow: depth * low for brow, low in brows.items()})
             for depth in depths]
    if all(turn is None for turn in turns):
        return None
    return Corrective(part, axis, turns, depths, frown)


def _turn_shape(runtime, guard: SliverGuard, number: int, high: float, axis: np.ndarray,
                frown: dict[int, float]) -> TurnShape | None:
    """Lid FAP ``number``'s shape with the brow FAPs ``frown``; None if it squeezes no watched corner
    up to ``high`` or does not turn past where it starts to."""
    onset = _onset(runtime, guard, number, high, frown)
    if onset >= high:
        return None
    angles, fixes = [], []
    for value in np.linspace(onset, high, STEPS + 1):
        positions, motion = _lid_pose(runtime, number, value, frown)
        watched = positions[guard.vertices]
        fixed = watched.copy()
        guard.constraints.guard(fixed)
        angles.append(turn_about(motion, axis))
        fixes.append(fixed - watched)
    angles = np.array(angles)
    turning = np.concatenate([[True], np.abs(angles[1:] - angles[0]) > np.abs(angles[:-1] - angles[0])])
    if turning.sum() < 2:
        return None
    return TurnShape(angles[turning], np.array(fixes)[turning])  # a lid past meeting turns no more


def _brows_lowered(runtime, number: int) -> dict[int, float]:
    """{brow FAP on lid ``number``'s side: its lowest value on this face} for those that lower
    the brow at all (none on a face without brow control points)."""
    low = runtime.faps.reach[0]
    return {brow: float(low[brow - 1]) for brow in FROWNS.get(number, ()) if low[brow - 1] < 0}


def _frown(runtime, guard: SliverGuard, brows: dict[int, float]) -> Frown | None:
    """How far ``brows`` (at their lowest) are lowered, read from the control points that DFFD
    spreads onto the watched skin and they move (the skin above the corner comes down through
    those whichever brow lowers it: the artists' brow motions reach across the face, so one brow
    lowered squeezes the other eye's corner a little too), blind to the lids' FAPs (an artist's
    blink moves some of those points too, and a closing lid's shape the margin's:
    ``FapEngine.closing_rows`` are left out)."""
    if not brows:
        return None
    rows = np.setdiff1d(runtime.points_moving(guard.vertices), runtime.faps.closing_rows)
    full = runtime.fap_controls(brows)[0][rows]
    moved = np.any(full != 0, axis=1)
    if not moved.any():
        return None
    rows, full = rows[moved], full[moved].ravel()
    lids = np.array([runtime.fap_controls({number: 1.0})[0][rows].ravel() for number in LID_FAPS]).T
    u, sigma, _ = np.linalg.svd(lids, full_matrices=False)
    basis = u[:, sigma > 1e-9 * sigma.max()] if sigma.max() > 0 else u[:, :0]
    across = full - basis @ (basis.T @ full)
    if across @ full <= 1e-9 * (full @ full):  # the frown moves these points only as the lids do
        return None
    return Frown(rows, (across / (across @ full)).reshape(-1, 3))


def _onset(runtime, guard: SliverGuard, number: int, high: float, frown: dict[int, float]) -> float:
    """The largest value of lid FAP ``number`` (to ``ONSET_TOLERANCE``), with the brow FAPs
    ``frown``, below which no watched corner is squeezed: the guard's first work is just above it.
    Scanned from open first (under a frown the squeeze can come and go as the lid turns), then
    bisected."""
    def squeezed(value: float) -> bool:
        return guard.constraints.squeezed(_lid_pose(runtime, number, value, frown)[0][guard.vertices])

    values = np.linspace(0.0, high, ONSET_SCAN + 1)
    first = next((k for k, value in enumerate(values) if squeezed(value)), None)
    if first is None:
        return high
    if first == 0:
        return 0.0
    low, high = values[first - 1], values[first]
    while high - low > ONSET_TOLERANCE:
        middle = 0.5 * (low + high)
        low, high = (low, middle) if squeezed(middle) else (middle, high)
    return low


def _lid_pose(runtime, number: int, value: float,
              frown: dict[int, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(the face's positions, the lid's rigid motion: the identity at rest) with FAP ``number``
    at ``value`` and the brow FAPs ``frown`` ({number: value}), as the runtime deforms them
    without a sliver guard."""
    controls, rigid = runtime.fap_controls({**(frown or {}), number: value})
    return runtime.deform(controls, rigid).astype(float), rigid.get(LID_FAPS[number][0], IDENTITY)
