"""Calibrate how each FAP moves the skin, from example shapes; fit and measure FAPs against them.

MPEG-4 leaves it to each face model to say how a FAP moves the skin around its feature point
(the FaceDefTables). Here the rig says it with ``fap_motions``: for every FAP, how far each point
of the skin grid (``puppet.face.autorig``: the active points no FAP moves by definition) moves per unit
of the FAP. ``calibrate`` learns them from example shapes (``puppet.face.examples``) of the same face:

* **Linearised at neutral.** A FAP vector f moves the skin by J0 f (the response of the rig
  without calibration, by central differences on the real runtime) plus B_G E f, where B_G are
  the DFFD columns of the grid points and E their motion per unit of each FAP.
* **Prior.** E starts from the coarse rig's motion (``build_rig(grid=False)``: feature points,
  lip lines and borders only, what the rig did before it had a grid), sampled at the grid points:
  a FAP that no example shows moves the skin as it always did. A rig that is calibrated already
  (the embedded face's, or a face's that ``puppet rig`` carried the calibration over to) starts
  from its own motions instead: a few examples of a new face refine them (``puppet
  calibrate-face``), and a FAP none of them shows keeps what it had.
* **Alternating least squares.** With E fixed, each example gets the FAP vector that reproduces
  it best within the FAPs' ranges (bounded least squares over every skin vertex, so motion where
  the example has none costs too). With those vectors fixed, E is the ridge solution pulled toward
  the prior and smooth across neighbouring grid points; both steps are exact and the second is
  closed-form (one generalised eigenproblem per axis). A translational FAP's motions stay in the
  regions of its feature point and those they drive. No motion moves a feature point along the
  axis of a FAP defined on it (``free_axes``), so each FAP still moves its own point by exactly
  value x FAPU along its direction and the encoder is unchanged.
* **Mirror tie.** On a face symmetric about x = 0 (the default face is, to the last digit on the
  skin) every example also teaches its mirror image, and after each motion solve E is made
  symmetric: a FAP moves the skin as its mirror FAP (``mirror_fap``: _l_ <-> _r_) moves the other
  side, mirrored. What the left shapes teach, the right side knows.
* **Gaze.** The gaze FAPs carry skin motion too (the lids and the skin around the eye follow the
  eyeball): their prior is a share of the eyeball's turn easing out from it (``LID_SHARE``).
* **Within the face's limits.** Where the rig has fold limits (``puppet.runtime.foldlimits``: each
  FAP's reach, and follow ranges for the differences of the inner and outer lip FAPs), every fit
  keeps within them, the follow ranges as linear constraints (``_bounded``), so the values found
  are those the face shows; the response is the rig's own, without the limits.
* **Held out.** ``HELD_OUT`` (whole left/right pairs and groups) or ``HELD_OUT_SIDE`` (every right
  shape) never reach a measuring calibration; the report gives their fit separately: a
  calibration that only memorises its examples is no win.

FAPs fitted: every low-level FAP that moves the skin (or whose prior does), except the head's
turns (the examples have the head still). The pupils and tongue of the default face are generated
(no example vertex on them), so neither they nor the eyeballs' thrust are fitted (``NOT_FITTED``).

Figures (``relative_residual``): |V(f) - V0 - D| / |D| over the vertices the example moves, with
V(f) the real (non-linear) rig; ``capacity`` is the same with every control point free (the best
any FAP definition could do with this layout).
"""

from __future__ import annotations

import copy
import functools
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from scipy.optimize import lsq_linear
from scipy.spatial import cKDTree

from puppet.face.autorig import build_rig
from puppet.face.rig import Rig
from puppet.fap.table import N_FAPS, clamp_ranges, fap, faps
from puppet.runtime import follow
from puppet.runtime.lids import LID_FAPS
from puppet.runtime.musclesolver import folded_triangles
from puppet.runtime.runtime import Runtime

HELD_OUT = ("browOuterUpLeft", "browOuterUpRight", "cheekSquintLeft", "cheekSquintRight",
            "mouthDimpleLeft", "mouthDimpleRight", "mouthPressLeft", "mouthPressRight",
            "eyeLookUpLeft", "eyeLookUpRight", "mouthRollLower", "mouthShrugUpper")
"""The group split: whole left/right pairs and groups that a measuring calibration never sees."""

HELD_OUT_SIDE = tuple(f"{stem}Right" for stem in (
    "browDown", "browOuterUp", "cheekSquint", "eyeBlink", "eyeLookDown", "eyeLookIn", "eyeLookOut",
    "eyeLookUp", "eyeSquint", "eyeWide", "jaw", "mouthDimple", "mouthFrown", "mouth", "mouthLowerDown",
    "mouthPress", "mouthSmile", "mouthStretch", "mouthUpperUp", "noseSneer"))
"""The side split: every shape of the face's right side. With the mirror tie the calibration
predicts each from its left twin (the MakeHuman right shapes are the left ones mirrored, to within
a few percent), so this split measures the tie and the fit; the group split measures
generalisation to motions no example showed."""

NOT_FITTED = (27, 28, 29, 30, 43, 44, 45, 46, 47, 48, 49, 50)
"""Eyeball thrust, pupils, tongue and head: no example shows them on the default face (module docstring)."""

GAZE = {23: ("eye_l", (0.0, 1.0, 0.0)), 24: ("eye_r", (0.0, 1.0, 0.0)),
        25: ("eye_l", (1.0, 0.0, 0.0)), 26: ("eye_r", (1.0, 0.0, 0.0))}
"""The gaze FAPs: the eyeball they turn and the axis it turns about (``puppet.runtime.fapengine``)."""

LID_SHARE = 0.5
"""The prior's share of an eyeball's turn that the skin at the eyeball's surface follows, easing
to nothing at twice the eyeball's radius (lids follow the gaze); calibration reshapes it."""

RIDGE = 1e-3
"""Weight of the smoothness term, relative to the data term's largest scale. Chosen on a
validation split inside the side split's training set (browDownLeft, eyeSquintLeft,
mouthFrownLeft, mouthUpperUpLeft, mouthStretchLeft, mouthShrugLower held out as well, linearised
fit): 1e-4 and 1e-3 validate alike (median 0.48), 1e-2 worse; the smoother one is kept (smoother
motions fold later). The relative weighting of examples left that split's median about where it
was (0.44 unweighted; three of its six shapes better, three worse)."""

KEEP = 0.01
"""Calibrated motions below this (in FAPU per FAPU: 1 = as far as the FAP's own point) are not stored."""

NEIGHBOURS = 6
"""Grid points a motion is compared with in the smoothness term."""

MU = 1e-2
"""Plain ridge beside the smoothness term (keeps it definite: a uniform motion costs a little)."""

STEP = 10.0
"""Central-difference step of the linearisation, in FAPU (AU for angles)."""


@dataclass
class Calibration:
    """A calibrated rig, the FAP vector fitted to each example and the examples held out."""

    rig: Rig
    weights: dict[str, np.ndarray]
    held_out: tuple[str, ...]
    fitted: tuple[int, ...]
    history: list[float] = field(default_factory=list)


def calibrate(face, examples: Mapping[str, np.ndarray], *, held_out: tuple[str, ...] = (),
              rig: Rig | None = None, iterations: int = 4, ridge: float = RIDGE,
              mirror: bool = True, limit_folds: bool = False) -> Calibration:
    """Calibrate ``rig`` (default: a new rig of ``face``) from ``examples`` {name: (N, 3)
    displacement}, leaving out ``held_out`` (``HELD_OUT_SIDE`` or ``HELD_OUT`` to measure; the
    shipped calibration uses every example); ``mirror`` ties the two sides (module docstring). ``limit_folds`` also stores each FAP's
    ``fold_free_reach`` in the rig, so that the runtime limits it there (off by default: limits
    found one FAP at a time also cap the FAPs that move together, and halve a smile)."""
    rig = copy.deepcopy(rig) if rig is not None else build_rig(face, calibrated=False)
    given, rig.fap_motions = rig.fap_motions, {}
    runtime = Runtime(face, rig, dtype=np.float64)
    model, E, history = solve(runtime, examples, held_out=held_out, iterations=iterations, ridge=ridge,
                              mirror=mirror, prior_motions=given)
    rig.fap_motions = model.motions(E)
    rig.fap_reach = fold_free_reach(Runtime(face, rig)) if limit_folds else {}
    calibrated = Runtime(face, rig, dtype=np.float64)
    weights = {name: fit_faps(calibrated, D_k) for name, D_k in examples.items() if np.any(D_k)}
    return Calibration(rig, weights, tuple(h for h in held_out if h in examples), model.fitted, history)


def solve(runtime: Runtime, examples: Mapping[str, np.ndarray], *, held_out: tuple[str, ...] = (),
          iterations: int = 4, ridge: float = RIDGE, mirror: bool = True,
          prior_motions: Mapping[int, Mapping[str, np.ndarray]] | None = None
          ) -> tuple[_LinearModel, list[np.ndarray], list[float]]:
    """The linear model of ``runtime``'s rig (no motions yet) on the skin, the motions E it learns
    from ``examples`` less ``held_out``, and the relative residual after each iteration. The prior
    is the coarse rig's motion, or for the FAPs ``prior_motions`` (a rig's ``fap_motions``) move,
    those: a calibrated rig is refined, not started again. With
    ``mirror`` (and a face symmetric about x = 0) each example also teaches its mirror image and
    E is kept symmetric: a FAP moves the skin as its mirror FAP does, mirrored. Each example
    weighs in the motion solve by its relative residual (a wink's few millimetres count as much
    as a jaw's centimetres), as the figures measure it."""
    face = runtime.face
    model = _LinearModel(runtime, _skin(face, runtime.rig),
                         Runtime(face, build_rig(face, grid=False, calibrated=False), dtype=np.float64))
    symmetry = model.symmetry if mirror else None
    shapes = [examples[name] for name in examples if name not in held_out and np.any(examples[name])]
    if symmetry is not None:
        shapes += [symmetry.field(D) for D in shapes]
    D = np.stack([model.rows(shape) for shape in shapes], axis=1)
    if prior_motions:
        model.prior_E = model.given(prior_motions)
    prior = model.prior_E
    E = prior
    history = []
    weight = 1.0 / np.linalg.norm(D, axis=0)
    for _ in range(iterations):
        F = np.stack([model.fit(E, D[:, k]) for k in range(D.shape[1])], axis=1)
        E = model.masked(model.solve_motions(F * weight, D * weight, prior, ridge), prior)
        if symmetry is not None:
            E = model.masked(symmetry.motions(E), prior)
        history.append(float(np.linalg.norm(model.predict(E, F) - D) / np.linalg.norm(D)))
    return model, E, history


def fit_faps(runtime: Runtime, displacement: np.ndarray, *, refine: int = 2, where: str = "skin",
             held: tuple[int, ...] = (), past_editor: tuple[int, ...] = ()) -> np.ndarray:
    """The 68 FAP values (within their ranges) whose pose best reproduces ``displacement`` (N, 3):
    bounded least squares linearised at neutral, then up to ``refine`` Gauss-Newton steps on the
    real rig, stopping at one that would fit worse (a blink's fit had stepped to opened lids);
    over the whole skin (``where="skin"``: motion where the shape has none costs too) or only
    the vertices it moves (``"moved"``, the measure of the rig's issue 11 baseline). The FAPs
    numbered in ``held`` stay at 0 (an expression's eyeballs, or the lips it leaves to the visemes).
    The FAPs numbered in ``past_editor`` are bounded by the face's own limits alone, not also by
    the Greta editor's slider range (``clamp_ranges``), which a file may pass: the artist's smile
    lifts the lip corners 746 MNS, and the editor's slider stops at 600."""
    skin = _skin(runtime.face, runtime.rig)
    if where == "moved":
        skin = skin[np.linalg.norm(displacement[skin], axis=1) > 0]
    elif where != "skin":
        raise ValueError(f"where {where!r}: expected 'skin' or 'moved'")
    model = _LinearModel(runtime, skin, held=held, past_editor=past_editor)
    target = model.rows(displacement)
    values = np.zeros(N_FAPS)
    rest = model.runtime.deform_faps(values)
    now = np.zeros_like(target)
    for step in range(refine + 1):
        J = model.response(values) if step else model.J0
        trial = values.copy()
        trial[model.columns] = _bounded(J, target - now + J @ values[model.columns], model.bounds, model.differences)
        shown = model.rows(model.runtime.deform_faps(trial) - rest)
        if step and np.linalg.norm(shown - target) >= np.linalg.norm(now - target):
            break  # the rig is not linear (lids turn, guards act): a step that fits worse is not taken
        values, now = trial, shown
    return values


def fold_free_reach(runtime: Runtime, *, steps: int = 12, numbers=None, reach=None) -> dict[int, tuple[float, float]]:
    """Per FAP, the values (low, high) it can take alone without folding a triangle: each end of
    its range (``clamp_ranges``; twice it, as files go beyond) is kept when nothing folds there,
    else the fold-free value found by bisection toward 0. FAPs that fold nowhere are left out;
    ``numbers`` restricts the search to those FAPs. The runtime's own reach does not apply, nor
    the fold guard's watch over its ``guarded`` triangles (the rig's response is searched);
    ``reach`` searches one end (``common_reach``) on a runtime without them
    (``puppet.runtime.foldsearch``), else each trial deforms the whole face."""
    if runtime.rig.fap_reach or len(runtime.rig.guarded):
        if reach is not None:
            raise ValueError("fold_free_reach: a given reach search needs a runtime without fap_reach or guarded")
        free = copy.copy(runtime.rig)
        free.fap_reach, free.guarded = {}, np.zeros(0, dtype=np.int64)
        runtime = Runtime(runtime.face, free, dtype=runtime.dtype)
    out = {}
    for f in faps():
        if f.number < 3 or (numbers is not None and f.number not in numbers):
            continue
        low, high = common_reach(runtime, [f.number], steps=steps, reach=reach)
        if np.isfinite(low) or np.isfinite(high):
            out[f.number] = (low, high)
    return out


def common_reach(runtime: Runtime, numbers: list[int], *, steps: int = 12, reach=None) -> tuple[float, float]:
    """The values (low, high) that the FAPs ``numbers`` moved together to the same value can take
    without folding a triangle, toward each end of the narrowest of their ranges (twice it, as in
    ``fold_free_reach``, which is this for one FAP); infinite toward an end where nothing folds.
    The runtime's own limits apply (pass one without them for the rig's response). ``reach``
    (numbers, end, steps) -> value or None searches one end on ``runtime``: ``bisected_reach``
    unless given (``puppet.runtime.foldsearch.FoldSearch`` finds the same with fewer trials)."""
    reach = reach or functools.partial(bisected_reach, runtime)
    lo, hi = clamp_ranges()
    index = np.asarray(numbers) - 1
    out = []
    for end, unlimited in ((np.max(lo[index]), -np.inf), (np.min(hi[index]), np.inf)):
        found = reach(numbers, 2 * end, steps) if np.isfinite(end) and end else None
        out.append(unlimited if found is None else float(found))
    return out[0], out[1]


def bisected_reach(runtime: Runtime, numbers: list[int], end: float, steps: int) -> float | None:
    """The largest fold-free value between 0 and ``end`` of the FAPs ``numbers`` together (None
    when ``end`` folds nothing): ``steps`` halvings from (0, ``end``), each trial the whole face
    deformed and every triangle tested, then the value rounded to 0.1 if that folds nothing."""
    triangles = np.asarray(runtime.face.triangles)

    def folds(value: float) -> bool:
        values = np.zeros(N_FAPS)
        values[np.asarray(numbers) - 1] = value
        return bool(folded_triangles(runtime.rest, runtime.deform_faps(values), triangles).any())

    if not folds(end):
        return None
    good, bad = 0.0, end
    for _ in range(steps):
        middle = (good + bad) / 2
        good, bad = (middle, bad) if not folds(middle) else (good, middle)
    return round(good, 1) if not folds(round(good, 1)) else good


def _unlimited(runtime: Runtime) -> Runtime:
    """The runtime itself, or one of the same face on a copy of its rig without ``fap_reach`` and
    ``fap_follow``: the rig's own response, which the fits linearise (they keep within the
    limits as bounds and constraints, where the face shows the values as they are)."""
    if not runtime.rig.fap_reach and not runtime.rig.fap_follow:
        return runtime
    rig = copy.copy(runtime.rig)
    rig.fap_reach, rig.fap_follow = {}, {}
    return Runtime(runtime.face, rig, dtype=runtime.dtype)


def relative_residual(runtime: Runtime, values: np.ndarray, displacement: np.ndarray) -> float:
    """|V(values) - V0 - D| / |D| over the vertices ``displacement`` moves, on the real rig."""
    moved = np.linalg.norm(displacement, axis=1) > 0
    error = runtime.deform_faps(values) - runtime.deform_faps(np.zeros(N_FAPS)) - displacement
    return float(np.linalg.norm(error[moved]) / np.linalg.norm(displacement[moved]))


def capacity(runtime: Runtime, displacement: np.ndarray) -> float:
    """The relative residual when every input control point moves freely (least squares on the
    DFFD matrix over the moved vertices): the best any FAP definition could do with this layout."""
    moved = np.linalg.norm(displacement, axis=1) > 0
    B = runtime.B[moved].toarray()
    best = np.linalg.lstsq(B, displacement[moved], rcond=None)[0]
    return float(np.linalg.norm(B @ best - displacement[moved]) / np.linalg.norm(displacement[moved]))


def _skin(face, rig: Rig) -> np.ndarray:
    """The vertices examples are measured on: the skin part, else every DFFD region."""
    if "skin" in face.parts:
        return np.asarray(face.parts["skin"], dtype=np.int64)
    return np.concatenate([r.vertices for r in rig.regions if r.kind == "dffd"]).astype(np.int64)


def _bounded(J: np.ndarray, b: np.ndarray, bounds: tuple[np.ndarray, np.ndarray],
             differences: list[tuple[int, int, np.ndarray]] = ()) -> np.ndarray:
    """argmin |J x - b| with x within ``bounds`` and, for each (i, j, rows) of ``differences``,
    (x_i, x_j) within the half-planes ``rows`` (the rig's follow pairs, ``puppet.runtime.follow``:
    within them the face shows the values as they are, so the fit is what the face does). A pair
    found outside is held on the half-plane it crossed most (x_i = alpha x_j + c, one unknown
    fewer) and the rest solved again, until every pair is inside; a held pair that ends past
    another of its half-planes is pinned where the two edges meet (the corner of its range)."""
    held: dict[int, tuple[int, float, float, float | None]] = {}
    while True:
        x = _held(J, b, bounds, held)
        crossed = {}
        for i, j, rows in differences:
            outside = rows[:, 0] * x[i] + rows[:, 1] * x[j] - rows[:, 2]
            k = int(np.argmax(outside))
            if outside[k] <= DIFFERENCE_TOLERANCE or (i in held and held[i][3] is not None):
                continue
            if i not in held:
                crossed[i] = (j, *_edge(rows[k]), None)
            else:
                on = int(np.argmin(np.abs(outside)))
                corner = np.linalg.solve(rows[[on, k], :2], rows[[on, k], 2])
                crossed[i] = (j, 0.0, float(corner[0]), float(corner[1]))
        if not crossed:
            return x
        held |= crossed


def _edge(row: np.ndarray) -> tuple[float, float]:
    """(alpha, c) of the half-plane's edge p x_i + q x_j = r as x_i = alpha x_j + c."""
    p, q, r = row
    return float(-q / p), float(r / p)


DIFFERENCE_TOLERANCE = 1e-6
"""FAPU by which a fitted pair may pass its follow range (``FapEngine.shown`` then moves it back
by as little)."""


def _held(J: np.ndarray, b: np.ndarray, bounds: tuple[np.ndarray, np.ndarray],
          held: dict[int, tuple[int, float, float, float | None]]) -> np.ndarray:
    """Bounded least squares with each x_i of ``held`` = alpha x_j + c ({i: (j, alpha, c, pin)}):
    x_i's column joins x_j's, and x_j keeps within both boxes; or, with a ``pin``, x_j = pin and
    x_i = c, both out of the solve."""
    low, high = (np.array(bound, dtype=float) for bound in bounds)
    K, rhs = J.copy(), b.copy()
    x = np.zeros(J.shape[1])
    for i, (j, alpha, c, pin) in held.items():
        if pin is not None:
            x[j] = pin
            rhs -= J[:, j] * pin
        K[:, j] += alpha * J[:, i]
        rhs -= J[:, i] * c
        ends = sorted(((low[i] - c) / alpha, (high[i] - c) / alpha)) if alpha else (-np.inf, np.inf)
        low[j], high[j] = max(low[j], ends[0]), min(high[j], ends[1])
        high[j] = max(high[j], low[j])
    pinned = {j for j, _, _, pin in held.values() if pin is not None}
    free = np.array([k for k in range(J.shape[1]) if k not in held and k not in pinned], dtype=np.int64)
    x[free] = lsq_linear(K[:, free], rhs, bounds=(low[free], high[free]), method="bvls", lsmr_tol="auto").x
    for i, (j, alpha, c, _) in held.items():
        x[i] = alpha * x[j] + c
    return x


class _LinearModel:
    """The rig on the skin, linearised at neutral: J0 (no calibration) and, per axis, the DFFD
    columns of the points free to move along it (``free``, module docstring); the FAPs numbered in
    ``held`` are left out."""

    def __init__(self, runtime: Runtime, skin: np.ndarray, coarse: Runtime | None = None,
                 held: tuple[int, ...] = (), past_editor: tuple[int, ...] = ()) -> None:
        self.runtime = _unlimited(runtime)  # the rig's response; its limits are the fits' bounds
        self.skin = skin
        self.columns = np.array([f.number - 1 for f in faps()
                                 if f.number > 2 and f.number not in NOT_FITTED and f.number not in held])
        self.fapu = np.array([runtime.face.fapu[fap(int(c) + 1).unit] for c in self.columns])
        self.J0 = self.response(np.zeros(N_FAPS))
        live = np.abs(self.J0).sum(axis=0) > 0
        if coarse is not None:
            self.prior_E = self._prior(coarse)
            live |= np.any([np.abs(E).sum(axis=0) > 0 for E in self.prior_E], axis=0)
            self.prior_E = [E[:, live] for E in self.prior_E]
        self.columns, self.J0, self.fapu = self.columns[live], self.J0[:, live], self.fapu[live]
        self.fitted = tuple(int(c) + 1 for c in self.columns)
        lo, hi = (end.copy() for end in clamp_ranges())
        past = [n - 1 for n in past_editor]
        lo[past], hi[past] = -np.inf, np.inf
        limits = runtime.faps
        reach = np.stack([np.maximum(limits.reach[0], limits.skin_reach[0]),
                          np.minimum(limits.reach[1], limits.skin_reach[1])])[:, self.columns]
        self.bounds = (np.maximum(lo[self.columns], reach[0]), np.minimum(hi[self.columns], reach[1]))
        index = {number: j for j, number in enumerate(self.fitted)}
        self.differences = [(index[a], index[b], follow.rows(*ranges)) for (a, b), ranges in sorted(runtime.rig.fap_follow.items())
                            if a in index and b in index]

    @functools.cached_property
    def free(self) -> list[list[int]]:
        return free_axes(self.runtime)

    @functools.cached_property
    def B(self) -> list[np.ndarray]:
        """Per axis, the skin rows of the DFFD matrix for the points free along it."""
        B = self.runtime.B[self.skin]
        return [B[:, self.free[a]].toarray() for a in range(3)]

    def rows(self, field: np.ndarray) -> np.ndarray:
        """A (N, 3) field on the skin as one column (x, y, z per skin vertex)."""
        return np.asarray(field)[self.skin].ravel()

    def response(self, values: np.ndarray, runtime: Runtime | None = None) -> np.ndarray:
        """d(vertices)/d(FAP) at ``values`` for the fitted FAPs on the skin, by central differences."""
        runtime = runtime or self.runtime
        J = np.empty((3 * len(self.skin), len(self.columns)))
        for j, c in enumerate(self.columns):
            step = STEP if fap(int(c) + 1).unit != "AU" else 100 * STEP
            up, down = values.copy(), values.copy()
            up[c] += step
            down[c] -= step
            J[:, j] = self.rows(runtime.deform_faps(up) - runtime.deform_faps(down)) / (2 * step)
        return J

    def _prior(self, coarse: Runtime) -> list[np.ndarray]:
        """Per axis, E (free points, fitted FAPs) in FAPU: the coarse rig's motion at each free
        point's vertex, less what this rig already gives it (a point riding on the jaw), and for
        the gaze FAPs the eyeball's turn, shared by the skin near it (``LID_SHARE``)."""
        skin_row = np.full(len(self.runtime.rest), -1)
        skin_row[self.skin] = np.arange(len(self.skin))
        coarse_J = self.response(np.zeros(N_FAPS), coarse)
        positions = self.runtime._p0[self.runtime._inputs]
        names = self.runtime.control_points
        out = []
        for a in range(3):
            rows = 3 * skin_row[[self.runtime.rig.point(names[i]).vertex for i in self.free[a]]] + a
            E = (coarse_J[rows] - self.J0[rows]) / self.fapu
            for j, c in enumerate(self.columns):
                if int(c) + 1 in GAZE:
                    E[:, j] = self._gaze(int(c) + 1, positions[self.free[a]])[:, a]
            out.append(E)
        return out

    def given(self, motions: Mapping[int, Mapping[str, np.ndarray]]) -> list[np.ndarray]:
        """``prior_E`` with the columns of the FAPs that ``motions`` (a rig's ``fap_motions``, in
        FAPU as ``motions`` writes them) move taken from them."""
        names = self.runtime.control_points
        out = []
        for a in range(3):
            E = self.prior_E[a].copy()
            for j, number in enumerate(self.fitted):
                table = motions.get(number)
                if table:
                    E[:, j] = [table[names[i]][a] if names[i] in table else 0.0 for i in self.free[a]]
            out.append(E)
        return out

    def _gaze(self, number: int, positions: np.ndarray) -> np.ndarray:
        """(P, 3): the motion per radian of ``positions`` when gaze FAP ``number`` turns its eyeball."""
        part, axis = GAZE[number]
        face = self.runtime.face
        centre = self.runtime.rig.rigid_parts[part].pivot
        radius = np.linalg.norm(face.vertices[face.parts[part]] - centre, axis=1).max()
        distance = np.linalg.norm(positions - centre, axis=1)
        share = LID_SHARE * np.clip(2.0 - distance / radius, 0.0, 1.0)
        return share[:, None] * np.cross(axis, positions - centre)

    @functools.cached_property
    def symmetry(self) -> _Mirror | None:
        """The face's left/right mirror on the skin, the free points and the fitted FAPs (None
        when the face is not symmetric about x = 0)."""
        return _Mirror.of(self)

    def fit(self, E: list[np.ndarray], target: np.ndarray) -> np.ndarray:
        """The fitted FAPs' values for one example column under motions E."""
        return _bounded(self.J(E), target, self.bounds, self.differences)

    def J(self, E: list[np.ndarray]) -> np.ndarray:
        """The skin's response to the fitted FAPs with motions E."""
        J = self.J0.reshape(len(self.skin), 3, -1).copy()
        for a in range(3):
            J[:, a, :] += self.B[a] @ (E[a] * self.fapu)
        return J.reshape(-1, len(self.columns))

    def predict(self, E: list[np.ndarray], F: np.ndarray) -> np.ndarray:
        return self.J(E) @ F

    def solve_motions(self, F: np.ndarray, D: np.ndarray, prior: list[np.ndarray], ridge: float) -> list[np.ndarray]:
        """argmin_E sum_k |J(E) f_k - d_k|^2 + lambda |(L + mu) (E - prior)|^2 per axis, L the
        grid's Laplacian (a motion unlike its neighbours' costs: smooth fields, no folds), in
        closed form through one generalised eigenproblem per axis."""
        Fs = F * self.fapu[:, None]  # FAP values in mesh units
        G = Fs @ Fs.T
        lam_f, P = np.linalg.eigh(G)
        lam_f = np.maximum(lam_f, 0.0)
        residual = (D - self.J0 @ F).reshape(len(self.skin), 3, -1)
        E = []
        for a in range(3):
            A = self.B[a].T @ self.B[a]
            M = self.smoothness[a]
            s, V = scipy.linalg.eigh(A, M)
            lam = ridge * s[-1] * lam_f[-1]
            R = residual[:, a, :] - self.B[a] @ prior[a] @ Fs
            core = (V.T @ (self.B[a].T @ R @ Fs.T) @ P) / (np.outer(s, lam_f) + lam)
            E.append(prior[a] + V @ core @ P.T)
        return E

    @functools.cached_property
    def smoothness(self) -> list[np.ndarray]:
        """Per axis, (L^T L + mu I) over the free points: L takes each point's motion less the mean
        of its ``NEIGHBOURS`` nearest free points' (rest positions)."""
        positions = self.runtime._p0[self.runtime._inputs]
        out = []
        for a in range(3):
            p = positions[self.free[a]]
            _, near = cKDTree(p).query(p, k=NEIGHBOURS + 1)
            L = np.eye(len(p))
            np.add.at(L, (np.repeat(np.arange(len(p)), NEIGHBOURS), near[:, 1:].ravel()), -1.0 / NEIGHBOURS)
            out.append(L.T @ L + MU * np.eye(len(p)))
        return out

    def masked(self, E: list[np.ndarray], prior: list[np.ndarray]) -> list[np.ndarray]:
        """E with each translational FAP's motions outside its regions put back to the prior's
        (nothing): a FAP shapes the regions that hold its feature point and those they drive."""
        return [np.where(self.allowed[a], E[a], prior[a]) for a in range(3)]

    @functools.cached_property
    def allowed(self) -> list[np.ndarray]:
        """Per axis, (free points, fitted FAPs): may the FAP move the point?"""
        rig = self.runtime.rig
        names = self.runtime.control_points
        region_of: dict[str, set[str]] = {}
        for region in rig.regions:
            for point in region.control_points:
                region_of.setdefault(point, set()).add(region.name)
        regions = []
        for number in self.fitted:
            f = fap(number)
            own = [p for p in f.feature_points if p in region_of] if f.axis is not None else []
            regions.append(set().union(*(_driven_regions(rig, p) for p in own)) if own else None)
        return [np.array([[r is None or region_of.get(names[i], set()) <= r for r in regions]
                          for i in self.free[a]]) for a in range(3)]

    def motions(self, E: list[np.ndarray]) -> dict[int, dict[str, np.ndarray]]:
        """E as the rig's ``fap_motions``: {FAP: {point: motion in FAPU}}, small ones dropped."""
        names = self.runtime.control_points
        out: dict[int, dict[str, np.ndarray]] = {}
        for j, number in enumerate(self.fitted):
            table: dict[str, np.ndarray] = {}
            for a in range(3):
                for i, value in zip(self.free[a], E[a][:, j]):
                    table.setdefault(names[i], np.zeros(3))[a] = value
            kept = {n: m for n, m in table.items() if np.linalg.norm(m) >= KEEP}
            if kept:
                out[number] = kept
        return out


def _driven_regions(rig: Rig, point: str) -> set[str]:
    """The regions that list ``point``, and every region their passive points carry motion into."""
    allowed = {r.name for r in rig.regions if point in r.control_points}
    while True:
        driven = {r.name for r in rig.regions
                  if any(rig.point(c).role == "passive" and rig.point(c).driver in allowed for c in r.control_points)}
        if driven <= allowed:
            return allowed
        allowed |= driven


def free_axes(runtime: Runtime) -> list[list[int]]:
    """Per axis (x, y, z), the active points a calibration may move along it: every active point,
    except along the axis of a FAP defined on it (that motion is the FAP's own, value x FAPU, and
    the encoder reads it back). The points a rigid FAP is measured on (the lids' centres, the
    chin) never move by calibration: a lid or the jaw turns them, and any motion of theirs would
    turn into the measured height."""
    own = runtime.faps._own.reshape(len(runtime.control_points), 3, N_FAPS).copy()
    measured = [point for _, point, _ in LID_FAPS.values()] + ["2.1"]
    for i, name in enumerate(runtime.control_points):
        if name in measured:
            own[i, :, 0] = 1.0
    return [[i for i in range(len(runtime.control_points)) if not own[i, a].any()] for a in range(3)]


FLIP = np.array([-1.0, 1.0, 1.0])
"""The mirror x -> -x of the MPEG-4 face frame (the face's own left and right swap)."""

SYMMETRIC = 1e-4
"""How far (relative to the face's size) a mirrored vertex or point may lie from its twin for the
face to count as symmetric."""

PAIRED = 0.95
"""The share of free points that must have a twin for the face to count as symmetric; the grid
(``puppet.face.autorig``) picks a few points off the mirror, and those keep their own motion."""


@dataclass
class _Mirror:
    """The left/right mirror of a linear model: each skin vertex's and free point's twin (per
    axis; -1 for a point without one), each fitted FAP's mirror FAP and the sign its value takes
    there (-1 for a FAP whose positive direction the mirror turns: shift_jaw, bend_nose, the
    gazes' yaw)."""

    vertex: np.ndarray
    points: list[np.ndarray]
    columns: np.ndarray
    signs: np.ndarray

    @classmethod
    def of(cls, model: _LinearModel) -> _Mirror | None:
        vertices = np.asarray(model.runtime.face.vertices, dtype=float)
        tolerance = SYMMETRIC * np.ptp(vertices, axis=0).max()
        distance, vertex = cKDTree(vertices).query(vertices * FLIP)
        if distance[model.skin].max() > tolerance:
            return None
        positions = model.runtime._p0[model.runtime._inputs]
        points = []
        for a in range(3):
            p = positions[model.free[a]]
            distance, twin = cKDTree(p).query(p * FLIP)
            paired = (distance <= tolerance) & (distance[twin] <= tolerance)
            if paired.mean() < PAIRED:
                return None
            points.append(np.where(paired, twin, -1))
        index = {number: j for j, number in enumerate(model.fitted)}
        columns = np.array([index.get(fap(mirror_fap(fap(n).name)).number, -1) for n in model.fitted])
        if (columns < 0).any():
            return None
        skin_row = np.full(len(vertices), -1)
        skin_row[model.skin] = np.arange(len(model.skin))
        twin_row = skin_row[vertex[model.skin]]
        if (twin_row < 0).any():
            return None
        response = model.J(model.prior_E).reshape(len(model.skin), 3, -1)
        mirrored = (response * FLIP[None, :, None])[twin_row]
        agree = np.einsum("vaj,vaj->j", mirrored, response[:, :, columns])
        return cls(vertex, points, columns, np.where(agree < 0, -1.0, 1.0))

    def field(self, displacement: np.ndarray) -> np.ndarray:
        """A displacement field (N, 3) mirrored: the shape the other side of the face makes."""
        return (np.asarray(displacement) * FLIP)[self.vertex]

    def motions(self, E: list[np.ndarray]) -> list[np.ndarray]:
        """E made symmetric: the mean of each FAP's motion and its mirror FAP's, mirrored."""
        out = []
        for a in range(3):
            paired = self.points[a] >= 0
            twin = FLIP[a] * E[a]
            twin[self.points[a][paired][:, None], self.columns[None, :]] = E[a][paired] * self.signs
            out.append((E[a] + FLIP[a] * twin) / 2)
        return out


def mirror_fap(name: str) -> str:
    """The FAP that mirrors ``name`` across the face: raise_l_cornerlip -> raise_r_cornerlip,
    lower_t_lip_lm -> lower_t_lip_rm; a FAP on the mid-line is its own mirror."""
    return re.sub(r"_([lr])(?=[_m])", lambda m: "_" + {"l": "r", "r": "l"}[m.group(1)], name)
