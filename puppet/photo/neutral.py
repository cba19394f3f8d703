"""A neutral face from a photo with an expression: the expression measured with the rig and
taken out of the landmarks before the face is shaped.

A smiling photo's landmarks carry two things at once: the performer's face and the smile. The
rig knows what an expression does to the default face (each FAP's motion), so the photo's
expression is measured as the encoder measures a take: the FAP values whose pose on the default
face's rig best explains the landmarks (``fit_expression``; bounded least squares, then
Gauss-Newton steps on the real rig). What the FAPs cannot explain is the performer's own shape,
which is smooth at the scale of the face: the fit is scored on what a heavily smoothed
thin-plate spline through the landmarks (``IDENTITY_SMOOTHING``) leaves over, so a broad
difference (a wider jaw, a longer nose) stays the performer's and only the local motion a FAP
makes is read as expression. Priors settle what one photo leaves open:

* a FAP costs a little (``FAP_COST``), so a face that only looks a little like a smile is not
  given one;
* the lips of a neutral face meet as the default face's do (``LIP_GAP_WEIGHT``), so parted lips
  are read as an open mouth, and its mouth corners sit level with the lips' middle
  (``CORNER_WEIGHT``), so raised corners are read as a smile;
* both sides move alike (``SYMMETRY_WEIGHT``).

Only the mouth and jaw FAPs are measured (``EXPRESSION_FAPS``): brows, lids and cheeks vary too
much from face to face to tell from one photo whether they moved. And only as much as the mouth
plainly shows an expression (``expression_shown``: lips parted or corners raised beyond the
default face's at rest): a closed-mouth photo is left as it is, since its lips' shape is the
performer's own.

``neutralise`` then takes the measured motion out of the landmarks. Around the mouth
(``MOUTH_REACH``) what neither the FAPs nor a smooth face explain (a stretched, thinned smiling
lip) is left out too: the neutral face has the default face's lips, scaled and placed as the
performer's own shape says, closed and relaxed; the photo's lips still colour them, since the
texture is read through the face as photographed (``puppet.photo.texture``).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.optimize import lsq_linear

from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.fap.table import N_FAPS, clamp_ranges, fap
from puppet.runtime.runtime import Runtime

EXPRESSION_FAPS = (3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 16, 17, 53, 54, 59, 60)
"""open_jaw, the inner lip FAPs, push lips, and the outer lip corners (which follow the inner)."""
IDENTITY_SMOOTHING = 3e-2  # thin-plate smoothing of the performer's own shape, face units squared
FAP_COST = 0.15  # what a FAP's own motion costs, against a landmark left unexplained: a pull toward none
LIP_GAP_WEIGHT = 3.0  # how firmly a neutral mouth's lips meet as the default face's do
LIP_PAIRS = (("2.2", "2.3"), ("2.7", "2.9"), ("2.6", "2.8"))  # inner lip points above / below
MIRRORED = ((6, 7), (8, 9), (10, 11), (12, 13), (53, 54), (59, 60))  # left and right FAP pairs
SYMMETRY_WEIGHT = 1.0  # how firmly a FAP and its mirror image move alike
CORNER_WEIGHT = 1.0  # how firmly a neutral mouth's corners sit level with its middle
MOUTH_REACH = (0.7, 1.1)  # mouth widths from its centre: the lips' own detail left out, fading out
SHOWN = (0.04, 0.1)  # mouth widths of parting or corner raise: from no expression to a plain one
REFINE = 2  # Gauss-Newton steps on the real rig after the linear fit
STEP = 20.0  # FAPU, the finite-difference step of the rig's response


def neutralise(face: Face, points, targets: np.ndarray, roles: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """(the 68 FAP values of the photo's expression, the landmark ``targets`` (M, 3, face frame)
    with its motion removed) for landmarks at ``points`` (``puppet.photo.build.MeshPoints``) on ``face``,
    the default face; ``roles`` name the rows of the inner lip feature points."""
    runtime = _runtime(face)
    rest = points.on(runtime.deform_faps(np.zeros(N_FAPS)))
    shown = expression_shown(face, rest, targets, roles)
    if shown == 0.0:
        return np.zeros(N_FAPS), targets
    values = shown * fit_expression(runtime, points, targets, roles)
    own = targets - points.on(runtime.deform_faps(values))  # the performer's own shape: offsets from the default
    mouth = shown * _mouth_weight(face, rest)
    return values, rest + (1.0 - mouth[:, None]) * own + mouth[:, None] * _scaled(rest, own, mouth)


def expression_shown(face: Face, rest: np.ndarray, targets: np.ndarray, roles: dict[str, int]) -> float:
    """How plainly the landmarks show an expression of the mouth, 0 to 1: the lips parted more
    than the default face's at rest, or the corners raised or lowered from the lips' middle
    more than its, each measured in mouth widths and ramped over ``SHOWN``. Without the inner
    lip points (the ``fdp11`` layout) nothing can be told: 0."""
    if not all(k in roles for k in ("2.2", "2.3", "2.4", "2.5")):
        return 0.0

    def mouth(p: np.ndarray) -> np.ndarray:
        upper, lower, left, right = (p[roles[k]] for k in ("2.2", "2.3", "2.4", "2.5"))
        width = np.linalg.norm(left - right)
        return np.array([upper[1] - lower[1], (left[1] + right[1] - upper[1] - lower[1]) / 2]) / width

    parted, raised = np.abs(mouth(targets) - mouth(rest))
    return float(np.clip((max(parted, raised) - SHOWN[0]) / (SHOWN[1] - SHOWN[0]), 0.0, 1.0))


def _scaled(rest: np.ndarray, own: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The part of ``own`` (M, 3) that scales and moves the landmarks where ``weight`` is
    (least squares per axis, weighted): the default face's lips at the performer's size."""
    w = weight / weight.sum()
    centre = w @ rest
    out = np.empty_like(own)
    for axis in range(3):
        x = rest[:, axis] - centre[axis]
        A = np.c_[x, np.ones(len(x))] * np.sqrt(w)[:, None]
        scale, shift = np.linalg.lstsq(A, own[:, axis] * np.sqrt(w), rcond=None)[0]
        out[:, axis] = scale * x + shift
    return out


def _mouth_weight(face: Face, rest: np.ndarray) -> np.ndarray:
    """Per landmark, 1 on and around the lips, fading to 0 a little beyond (``MOUTH_REACH``):
    where the neutral face takes the default face's lips, scaled to the performer's."""
    fp = face.feature_points
    centre, width = (fp["2.4"] + fp["2.5"]) / 2, np.linalg.norm(fp["2.4"] - fp["2.5"])
    reach = np.linalg.norm((rest - centre)[:, :2], axis=1) / width
    return np.clip((MOUTH_REACH[1] - reach) / (MOUTH_REACH[1] - MOUTH_REACH[0]), 0.0, 1.0)


def fit_expression(runtime: Runtime, points, targets: np.ndarray, roles: dict[str, int]) -> np.ndarray:
    """The FAP values (68, FAPU; only ``EXPRESSION_FAPS`` nonzero) that best explain ``targets``
    as the default face plus a smooth shape of its own (module docstring)."""
    rest = points.on(runtime.deform_faps(np.zeros(N_FAPS)))
    columns = np.array([n - 1 for n in EXPRESSION_FAPS])
    smooth = np.kron(_residual_operator(rest), np.eye(3))
    units = np.array([runtime.face.fapu[fap(n).unit] for n in EXPRESSION_FAPS])
    on_shape, on_values = _mouth_rows(roles, len(rest)), _mirror_rows(units)
    values = np.zeros(N_FAPS)
    for _ in range(REFINE + 1):
        J = _response(runtime, points, values, columns)
        # the performer's own shape is ``wanted - J f``, linearised about ``values``
        wanted = (targets - points.on(runtime.deform_faps(values))).ravel() + J @ values[columns]
        rows = [smooth @ J, on_shape @ J, np.diag(FAP_COST * units), on_values]
        goals = [smooth @ wanted, on_shape @ wanted, np.zeros(len(columns)), np.zeros(len(on_values))]
        values[columns] = lsq_linear(np.vstack(rows), np.concatenate(goals), bounds=_bounds(runtime, columns)).x
    return values


def _mouth_rows(roles: dict[str, int], count: int) -> np.ndarray:
    """Weighted rows (R, 3 M) of priors on the performer's own shape at the mouth, each to be
    0: the lips of a neutral face meet as the default face's (both lips' own shape moves alike,
    in height and depth), and its corners sit level with the lips' middle."""
    rows = []
    for upper, lower in LIP_PAIRS:
        if upper in roles and lower in roles:
            for axis in (1, 2):
                row = np.zeros(3 * count)
                row[3 * roles[upper] + axis], row[3 * roles[lower] + axis] = LIP_GAP_WEIGHT, -LIP_GAP_WEIGHT
                rows.append(row)
    if all(k in roles for k in ("2.2", "2.3", "2.4", "2.5")):
        for corner in ("2.4", "2.5"):
            row = np.zeros(3 * count)
            row[3 * roles[corner] + 1] = CORNER_WEIGHT
            row[3 * roles["2.2"] + 1] = row[3 * roles["2.3"] + 1] = -CORNER_WEIGHT / 2
            rows.append(row)
    return np.array(rows).reshape(-1, 3 * count)


def _mirror_rows(units: np.ndarray) -> np.ndarray:
    """Weighted rows (R, K) of a prior on the FAP values, each to be 0: a FAP and its mirror
    image move alike (their motions in face units)."""
    rows = np.zeros((len(MIRRORED), len(EXPRESSION_FAPS)))
    for k, (left, right) in enumerate(MIRRORED):
        i, j = EXPRESSION_FAPS.index(left), EXPRESSION_FAPS.index(right)
        rows[k, i], rows[k, j] = SYMMETRY_WEIGHT * units[i], -SYMMETRY_WEIGHT * units[j]
    return rows


def _response(runtime: Runtime, points, values: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """d(landmark positions)/d(FAP) at ``values``: (3 M, K), rows x, y, z per landmark."""
    J = []
    for c in columns:
        up, down = values.copy(), values.copy()
        up[c] += STEP
        down[c] -= STEP
        J.append((points.on(runtime.deform_faps(up)) - points.on(runtime.deform_faps(down))).ravel() / (2 * STEP))
    return np.stack(J, axis=1)


def _residual_operator(sites: np.ndarray) -> np.ndarray:
    """(M, M): what a heavily smoothed thin-plate spline through values at ``sites`` leaves
    over: I - H, H the spline's hat matrix."""
    n = len(sites)
    return np.eye(n) - RBFInterpolator(sites, np.eye(n), kernel="thin_plate_spline", smoothing=IDENTITY_SMOOTHING)(sites)


def _bounds(runtime: Runtime, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The FAPs' ranges where the table gives them, within what the face shows without a fold."""
    lo, hi = clamp_ranges()
    reach = runtime.faps.reach[:, columns]
    low, high = np.maximum(lo[columns], reach[0]), np.minimum(hi[columns], reach[1])
    return np.where(np.isfinite(low), low, -2048.0), np.where(np.isfinite(high), high, 2048.0)


@functools.cache
def _default_runtime() -> Runtime:
    return Runtime(load_face())


def _runtime(face: Face) -> Runtime:
    """The default face's runtime (made once), or a runtime of ``face`` if it is another."""
    default = _default_runtime()
    return default if face.content_hash == default.face.content_hash else Runtime(face)
