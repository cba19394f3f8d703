"""``puppet bench --only rig``: how long ``puppet rig`` takes, and its fold-limit search before
and after ``puppet.runtime.foldsearch``, timed in the same run on the same face.

Per face (the default face; the ICT head, 26,719 vertices, when the shared assets are there):
reading and rigging it (``load_face`` and ``build_rig``, what ``puppet rig`` does before its
limits), then its fold limits (``foldlimits.fold_limited``) with the plain search
(``foldsearch.Bisection``: every trial the whole face, every follow a new runtime, as the
search was before) and with ``FoldSearch``; medians over the runs, the ratio, and whether the two
found the same limits to the digit.
"""

from __future__ import annotations

import statistics
import time

from puppet.bench.ict import ict_inputs
from puppet.face.autorig import build_rig
from puppet.face.load import load_face
from puppet.runtime.foldlimits import fold_limited
from puppet.runtime.foldsearch import Bisection, FoldSearch


def bench_rig(runs: int = 3, before_runs: int = 1, ict: bool = True) -> list[dict]:
    """A row per face: its vertices, ``rig_s`` (read and rig, median of ``runs``), ``before_s``
    (the plain search, median of ``before_runs``: a minute on ICT), ``after_s`` (``FoldSearch``,
    median of ``runs``), their ratio, ``total_s`` (rig_s + after_s: ``puppet rig`` less writing
    the folder) and ``same`` (the limits agree to the digit)."""
    faces = [("default", lambda: load_face())]
    found = ict_inputs() if ict else None
    if found is not None:
        faces.append(("ict", lambda: load_face(found[0], landmarks=found[1])))
    rows = []
    for name, read in faces:
        rigged = []
        for _ in range(runs):
            start = time.perf_counter()
            face = read()
            rig = build_rig(face)
            rigged.append(time.perf_counter() - start)
        after, limits = _searched(face, rig, FoldSearch, runs)
        before, reference = _searched(face, rig, Bisection, before_runs)
        rig_s = statistics.median(rigged)
        rows.append({"face": name, "vertices": len(face.vertices), "rig_s": rig_s, "before_s": before,
                     "after_s": after, "ratio": before / after, "total_s": rig_s + after,
                     "same": limits == reference})
    return rows


def _searched(face, rig, search, runs: int) -> tuple[float, tuple]:
    """(median seconds of ``fold_limited`` with ``search``, the (follow, reach) it found)."""
    times = []
    for _ in range(max(runs, 1)):
        start = time.perf_counter()
        limited = fold_limited(face, rig, search=search)
        times.append(time.perf_counter() - start)
    return statistics.median(times), (limited.fap_follow, limited.fap_reach)
