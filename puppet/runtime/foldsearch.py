"""Where a FAP starts to fold the skin, found with few deformations of the face: the fold-limit
search of ``puppet.runtime.foldlimits``, fast enough for ``puppet rig``.

The limits ask, for each FAP alone (and each lip pair moved together) toward each end of its
range, for the largest value that folds no triangle: twelve halvings of (0, twice the range end),
then that value rounded to 0.1 (``fapcalibration.bisected_reach``). Done plainly (``Bisection``),
every trial deforms the whole face and tests every triangle, and every follow the limits try
sets up a new runtime: on the ICT head (26,719 vertices) 3,500 deformations and seven runtimes,
48-76 s. ``FoldSearch`` gives the same values from a few deformations:

* **A model of the motion between trials.** The face deformed at the values tried so far
  (0 and the range end to start with), interpolated linearly between them: a FAP's DFFD motion is
  linear in its value, so for most FAPs the model is the face itself; a jaw's or lid's turn and a
  lip pair's follow bend it, and trials added there straighten it. On a stretch where the vertices
  move linearly, a triangle's normal is a quadratic in the value, so the model tests a trial with a
  few products per triangle, and only on the triangles that came near folding on the faces tried
  (``NEAR``): a model that misses a fold is caught by the check below, and where the motion is
  linear it makes none up.
* **Checked on the face.** The bisection runs on the model; its last bracket (good, bad) is then
  deformed for real: good must fold nothing and bad must fold. Where both hold, every halving of
  the plain bisection goes the same way (its trials below good fold nothing and those from bad on
  fold, as the values that fold nothing run on from 0: the plain search assumes it too); where one
  does not, that trial joins the model and the bisection runs again. The rounded value is tried on
  the face where it lies inside the bracket. A face tried is tested only on the triangles whose
  corners moved far enough to turn them over (``FoldSearch.touched``): its answer is the whole
  face's. A linear FAP costs three or four deformations, a lip FAP whose pair follows five to
  nine, a lid twenty.
* **Each search once.** A FAP's reach depends only on the follow of the lip pairs it belongs to
  (``foldlimits``' follow moves a pair's other FAP, and nothing else): a search is kept by its FAPs,
  end and those follows, and a FAP outside the pairs is searched once for all three follows the
  limits try. A new follow is a new FAP engine on the same runtime (``Runtime.with_limits``).

* **On every core.** The limits ask for every FAP's two ends whatever each finds, so
  ``FoldSearch.ahead`` searches them all at once in processes forked from this one
  (``puppet.runtime.forked``: they inherit the runtime; nothing is sent but the ends and the
  values), one per core.
* **Only what moves.** A FAP moves the same inputs at every value tried (1,100-1,700 of ICT's
  3,540), so the search's runtime spreads only theirs (``Runtime.for_few_inputs``: B's columns
  for them gathered once, the same sums less the zero terms); a face tried is tested with its
  corners gathered a coordinate at a time, and the model's cross products are written out.

On the ICT head the search takes 916 deformations and one runtime: 1.5 s of CPU in one process
(2.6 s before it spread only what moves: ``fold_limits`` on ICT's smoothed rig, median of three
runs in turns, this 2-core machine busy), 3-4 s of wall on two cores before it (``puppet bench
--only rig`` times it beside the plain search in one run: 41.8 -> 3.1 s, and 54.5 -> 3.9 s in a
slower hour); the limits are the plain search's to the digit, on ICT and on the default face
(``tests/test_foldsearch.py``). Trusting the model's answer at bad where the face at good lay on
its line to 1e-5 would save a deformation a limit, but moved one limit of the default face by
0.3 MNS (a fold is a near-cancellation: the model's error counts against the triangle's size,
not the motion's), so every bracket is checked. The check holds
where the face, once folded, stays folded further on; it does not quite everywhere (FAP 59
alone folds at -358.5 MNS on the default face, not at -358.6): trying the rounded value in
good's stead moved that limit by 0.3 MNS, so good itself is tried, as the plain search did.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable

import numpy as np

from puppet.fap.table import N_FAPS
from puppet.runtime.fapcalibration import bisected_reach
from puppet.runtime.forked import forked_map
from puppet.runtime.runtime import Runtime

CLEAR = 0.5
"""The share of a triangle's rest |n0|^2 that ``FoldSearch.touched`` keeps as the margin of one it
leaves out: far beyond rounding, so its fold test is the whole face's to the last bit."""
NEAR = 0.5
"""A triangle whose normal . rest normal falls below this share of |n0|^2 on a face tried is one
the model follows on the stretches beside it."""


class Bisection:
    """The plain search (``fapcalibration.bisected_reach``), each follow on a new runtime: the
    reference ``FoldSearch`` keeps to and the benchmark's "before"."""

    def __init__(self, runtime: Runtime) -> None:
        self.runtime = runtime

    def __call__(self, numbers: list[int], end: float, steps: int) -> float | None:
        """The largest fold-free value of ``numbers`` together between 0 and ``end`` (None when
        ``end`` folds nothing), as ``fapcalibration.common_reach`` asks for one."""
        return bisected_reach(self.runtime, numbers, end, steps)

    def ahead(self, ask: Callable[[Callable], object]) -> None:
        """Nothing: the plain search finds each end when it is asked for it (``FoldSearch.ahead``
        finds them all at once)."""

    def with_follow(self, fap_follow: dict) -> Bisection:
        """The same search on the face under other follow ranges (a new runtime)."""
        rig = self.runtime.with_limits(fap_follow).rig
        return type(self)(Runtime(self.runtime.face, rig, dtype=self.runtime.dtype))


class FoldSearch(Bisection):
    """``Bisection``'s values from a model of the motion checked on the face (module docstring)."""

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime.for_few_inputs())  # a search deforms one FAP at a dozen values
        self.triangles = np.asarray(runtime.face.triangles, dtype=np.int64)
        self._corners = [np.ascontiguousarray(self.triangles[:, k]) for k in range(3)]
        rest = np.asarray(runtime.rest, dtype=float)
        self.rest_normals = _normals(rest, self.triangles)
        a, b, c = (rest[corner] for corner in self._corners)
        size = np.linalg.norm(b - a, axis=1) + np.linalg.norm(c - a, axis=1)
        self._area = np.linalg.norm(self.rest_normals, axis=1)
        self._clear = ((np.sqrt(size * size + 4 * CLEAR * self._area) - size) / 4) ** 2
        self._near = NEAR * self._area ** 2
        self._rest_normals_t = np.ascontiguousarray(self.rest_normals.T)  # (3, T): ``_dots`` by rows
        self._found: dict[tuple, float | None] = {}

    def with_follow(self, fap_follow: dict) -> FoldSearch:
        """The same search on the face under other follow ranges: the runtime shares everything but
        its FAP engine, and searches whose FAPs the change does not touch are kept."""
        other = object.__new__(type(self))
        other.__dict__.update(self.__dict__)
        other.runtime = self.runtime.with_limits(fap_follow)
        return other

    def __call__(self, numbers: list[int], end: float, steps: int) -> float | None:
        """``Bisection``'s value, found once per FAPs, end and follow of the pairs they are in."""
        key = self._key(numbers, end, steps)
        if key not in self._found:
            self._found[key] = _Trials(self, numbers, end).reach(steps)
        return self._found[key]

    def ahead(self, ask: Callable[[Callable], object]) -> None:
        """Search at once every end that ``ask(reach)`` will ask this search for and that is not
        known yet, on every core (``puppet.runtime.forked``: each process inherits the runtime):
        ``ask`` is run first with a reach that only notes what it is asked for (the limits ask
        for every FAP's two ends whatever each finds). The values are the ones asked one by one
        (``tests/test_foldsearch.py``); where the processes cannot fork or do not answer in time,
        the ends are searched here."""
        asked: dict[tuple, tuple[list[int], float, int]] = {}

        def note(numbers: list[int], end: float, steps: int) -> None:
            asked[self._key(numbers, end, steps)] = (list(numbers), end, steps)

        ask(note)
        todo = {key: args for key, args in asked.items() if key not in self._found}

        def search(args: tuple[list[int], float, int]) -> float | None:
            numbers, end, steps = args
            return _Trials(self, numbers, end).reach(steps)

        self._found.update(zip(todo, forked_map(search, list(todo.values()))))

    def _key(self, numbers: list[int], end: float, steps: int) -> tuple:
        """What a search's value depends on: its FAPs, end, steps and the follow of their pairs."""
        follow = self.runtime.rig.fap_follow
        theirs = tuple(sorted((pair, follow[pair]) for pair in follow if set(pair) & set(numbers)))
        return tuple(numbers), end, steps, theirs

    def moved(self, face: np.ndarray) -> np.ndarray:
        """How far each vertex of ``face`` (the whole face, as the runtime gives it) lies from rest,
        squared (in the runtime's precision: ``touched`` keeps a wide margin)."""
        step = face - self.runtime.rest
        return np.einsum("ij,ij->i", step, step)

    def folds(self, face: np.ndarray, moved: np.ndarray,
              likely: np.ndarray | None = None) -> tuple[bool, np.ndarray]:
        """Does any triangle of ``face`` (the whole face, as the runtime gives it; its vertices
        ``moved`` from rest, squared) turn against its rest normal, and which come near it (normal
        . rest normal below ``NEAR`` of |n0|^2)? Only those that might fold (``touched``) are
        tested, the ``likely`` ones first: where one of them folds, that is the answer (and they
        the near ones)."""
        if likely is not None and len(likely):
            dots = self._dots(face, likely)
            if (dots < 0).any():
                return True, likely[dots < self._near[likely]]
        touched = self.touched(moved)
        dots = self._dots(face, touched)
        return bool((dots < 0).any()), touched[dots < self._near[touched]]

    def _dots(self, face: np.ndarray, among: np.ndarray) -> np.ndarray:
        """Each triangle of ``among``'s normal on ``face`` dotted with its rest normal, as
        ``musclesolver.folded_triangles`` takes them: the corners gathered a coordinate at a time
        into contiguous rows (2-3x faster than gathering them triangle by triangle)."""
        p0, p1, p2 = (np.take(face.T, corner[among], axis=1).astype(float) for corner in self._corners)
        (bx, by, bz), (cx, cy, cz) = p1 - p0, p2 - p0
        nx, ny, nz = np.take(self._rest_normals_t, among, axis=1)
        return (by * cz - bz * cy) * nx + (bz * cx - bx * cz) * ny + (bx * cy - by * cx) * nz

    def touched(self, moved: np.ndarray) -> np.ndarray:
        """The triangles that might fold with their corners moved at most sqrt(``moved``) (per
        vertex) from rest: with its corners moved at most d, a triangle's normal n keeps n . n0 >=
        |n0|^2 - |n0| (2 d (|e1| + |e2|) + 4 d^2) (n0, e1, e2 its rest normal and edges). The
        others stay well clear (``CLEAR`` of their rest |n0|^2: d below sqrt(``_clear``)), so
        testing only these gives the whole face's answer."""
        a, b, c = self._corners
        d = np.maximum(np.maximum(moved[a], moved[b]), moved[c])
        return np.flatnonzero(d >= self._clear)


class _Trials:
    """One end's search: the values deformed for real so far, their faces, whether they fold and
    which triangles came near it there, and the model between them (``FoldSearch``)."""

    def __init__(self, search: FoldSearch, numbers: list[int], end: float) -> None:
        self.search, self.numbers, self.end = search, numbers, end
        self.faces = {0.0: search.runtime.rest}
        self.near = {0.0: np.zeros(0, dtype=np.int64)}
        self._tried = [0.0]  # |value| of each value tried, sorted
        self.folded = {0.0: False}
        self._stretches: dict[tuple[float, float], tuple[np.ndarray, ...]] = {}

    def reach(self, steps: int) -> float | None:
        """``bisected_reach``'s value: None when the end folds nothing, else the last fold-free
        value of the bisection, rounded to 0.1 where that folds nothing."""
        if not self.real(self.end):
            return None
        while True:
            good, bad = 0.0, self.end
            for _ in range(steps):
                middle = (good + bad) / 2
                good, bad = (middle, bad) if not self.modelled(middle) else (good, middle)
            if not self.real(good) and self.real(bad):
                break
        rounded = round(good, 1)
        if abs(rounded) <= abs(good):
            return rounded
        if abs(rounded) >= abs(bad):
            return good
        return rounded if not self.real(rounded) else good

    def real(self, value: float) -> bool:
        """Does the face fold at ``value``? Deformed once, then known."""
        if value not in self.folded:
            values = np.zeros(N_FAPS)
            values[np.asarray(self.numbers) - 1] = value
            face = self.search.runtime.deform_faps(values)
            likely = self._folding(value) if abs(value) < abs(self.end) else None
            self.faces[value] = face
            bisect.insort(self._tried, abs(value))
            self.folded[value], self.near[value] = self.search.folds(face, self.search.moved(face), likely)
        return self.folded[value]

    def modelled(self, value: float) -> bool:
        """Does the model fold at ``value``: the faces deformed at the nearest values tried on
        either side, interpolated linearly (the real answer at a value tried)?"""
        if value in self.folded:
            return self.folded[value]
        return len(self._folding(value)) > 0

    def _folding(self, value: float) -> np.ndarray:
        """The triangles the model folds at ``value`` (between 0 and the end, not tried)."""
        before, beyond = self._around(value)
        a, b, c, triangles = self._stretch(before, beyond)
        s = (value - before) / (beyond - before)
        return triangles[a + s * (b + s * c) < 0]

    def _around(self, value: float) -> tuple[float, float]:
        """The values tried nearest ``value`` (not tried itself) on either side: all lie between 0
        and the end."""
        tried = self._tried
        before, beyond = tried[bisect.bisect_left(tried, abs(value)) - 1], tried[bisect.bisect_right(tried, abs(value))]
        return math.copysign(before, self.end), math.copysign(beyond, self.end)

    def _stretch(self, before: float, beyond: float) -> tuple[np.ndarray, ...]:
        """(a, b, c, triangles): on the stretch from ``before`` to ``beyond``, each triangle near
        folding at either end (``FoldSearch.folds``) has normal . rest normal = a + b s + c s^2 at
        s in 0..1. A triangle that folds only inside the stretch is missed, and then the check on
        the face finds the model wrong: the model can miss a fold, never make one up where it is
        linear."""
        key = (before, beyond)
        if key not in self._stretches:
            search = self.search
            touched = np.union1d(self.near[before], self.near[beyond])
            corners = search.triangles[touched]
            p = self.faces[before][corners].astype(float)
            d = self.faces[beyond][corners].astype(float) - p
            e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
            d1, d2 = d[:, 1] - d[:, 0], d[:, 2] - d[:, 0]
            n0 = search.rest_normals[touched]
            a = np.einsum("ij,ij->i", _cross(e1, e2), n0)
            b = np.einsum("ij,ij->i", _cross(e1, d2) + _cross(d1, e2), n0)
            c = np.einsum("ij,ij->i", _cross(d1, d2), n0)
            self._stretches[key] = (a, b, c, touched)
        return self._stretches[key]


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``np.cross(u, v)`` of (T, 3) arrays: its products and differences, in its order, without
    its axis handling (which cost more than the arithmetic on the model's few hundred triangles)."""
    out = np.empty_like(u)
    (u0, u1, u2), (v0, v1, v2) = u.T, v.T
    for k, (a, b, c, d) in enumerate(((u1, v2, u2, v1), (u2, v0, u0, v2), (u0, v1, u1, v0))):
        np.multiply(a, b, out=out[:, k])
        out[:, k] -= c * d
    return out


def _normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Each triangle's (unnormalised) normal, as ``musclesolver.folded_triangles`` takes it."""
    return np.cross(positions[triangles[:, 1]] - positions[triangles[:, 0]],
                    positions[triangles[:, 2]] - positions[triangles[:, 0]])
