"""How the displacements of a rig's driven points spread to every control point.

The runtime is given displacements of its *input* points: the active control points, then the
fixed points a rigid part carries (``Rig.input_points``). Other fixed points stay put;
points interpolated along a lip line follow the line's key points by Catmull-Rom interpolation
(a cubic Bezier through the keys, parametrised by the keys' rest positions); passive points
follow the DFFD of their driver region. All three are linear in the active displacements, so
they fold into one small dense matrix ``M`` (all points x inputs): D_all = M @ D_inputs.
"""

from __future__ import annotations

import numpy as np

from puppet.face.rig import Rig, RigError


def catmull_rom_weights(u: float) -> np.ndarray:
    """Weights of the four keys around a segment at local parameter u in [0, 1]."""
    u2, u3 = u * u, u * u * u
    return np.array([
        -0.5 * u3 + u2 - 0.5 * u,
        1.5 * u3 - 2.5 * u2 + 1.0,
        -1.5 * u3 + 2.0 * u2 + 0.5 * u,
        0.5 * u3 - 0.5 * u2,
    ])


def lip_line_weights(keys: np.ndarray, point: np.ndarray) -> dict[int, float]:
    """Weights over key indices that place ``point`` on the curve through ``keys`` (rest positions).

    The point is projected onto the polyline of keys to find its segment and local parameter;
    the ends are clamped (the first and last key stand in for their missing neighbours).
    """
    seg, u = _closest_segment(keys, point)
    n = len(keys)
    around = [max(seg - 1, 0), seg, seg + 1, min(seg + 2, n - 1)]
    weights: dict[int, float] = {}
    for key, w in zip(around, catmull_rom_weights(u)):
        weights[key] = weights.get(key, 0.0) + float(w)
    return weights


def _closest_segment(keys: np.ndarray, point: np.ndarray) -> tuple[int, float]:
    a, b = keys[:-1], keys[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", point - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    dist = np.linalg.norm(a + t[:, None] * ab - point, axis=1)
    seg = int(np.argmin(dist))
    return seg, float(t[seg])


def spread_matrix(rig: Rig, passive_rows: dict[str, dict[str, float]]) -> np.ndarray:
    """M (all points x inputs) with D_all = M @ D_inputs.

    ``passive_rows`` gives, for each passive point, its DFFD coefficients over the control points
    of its driver region. Dependencies are resolved in order; a cycle is a rig error.
    """
    index = rig.point_index()
    active = {name: i for i, name in enumerate(rig.input_points)}
    depends = _dependencies(rig, passive_rows)
    M = np.zeros((len(rig.control_points), len(active)))  # each row filled in place (a 27k-vertex
    rows: dict[str, np.ndarray] = {}  # face's M is 3,750 x 3,540: a copy of it costs a tenth of a second)
    pending = [p.name for p in rig.control_points]
    while pending:
        ready = [n for n in pending if all(d in rows for d in depends.get(n, {}))]
        if not ready:
            raise RigError(f"control points depend on each other in a cycle: {sorted(pending)[:6]}")
        for name in ready:
            rows[name] = M[index[name]]
            _fill(rows[name], rig.control_points[index[name]].role, name, active, depends, rows)
        pending = [n for n in pending if n not in rows]
    return M


def _dependencies(rig: Rig, passive_rows: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    depends: dict[str, dict[str, float]] = dict(passive_rows)
    for line in rig.lip_lines:
        keys = np.array([rig.point(k).position for k in line.keys])
        for name in line.points:
            weights = lip_line_weights(keys, rig.point(name).position)
            depends[name] = {line.keys[i]: w for i, w in weights.items()}
    return depends


def _fill(row: np.ndarray, role: str, name: str, active: dict[str, int], depends: dict, rows: dict) -> None:
    """Point ``name``'s row of M, written into ``row`` (zeros): 1 at its own input, or its sources'
    rows weighted (``rows``: those made so far)."""
    if name in active:
        row[active[name]] = 1.0
    elif role in ("passive", "interpolated"):
        for source, weight in depends[name].items():
            row += weight * rows[source]
