"""Midpoint subdivision of a Face that keeps everything indexed into it valid.

Each triangle of the chosen parts (by default the skin, the surface that deforms) becomes four;
the old vertices keep their indices and each split edge's midpoint is appended, so feature points, pivots and part membership carry over. A midpoint belongs to a part
when both ends do, and contours gain the midpoints of their own edges so they stay closed edge
loops. Texture coordinates and source indices are not carried (the result is for measuring how
the runtime scales with the vertex count, not for rendering with a texture).
"""

from __future__ import annotations

import numpy as np

from puppet.face.model import Face


def subdivide(face: Face, times: int = 1, parts: tuple[str, ...] = ("skin",)) -> Face:
    """The face with the triangles of ``parts`` subdivided ``times`` times (each time ~4x)."""
    for _ in range(times):
        face = _subdivide_once(face, parts)
    return face


def _subdivide_once(face: Face, parts: tuple[str, ...]) -> Face:
    n = len(face.vertices)
    chosen = np.zeros(n, dtype=bool)
    for part in parts:
        chosen[face.parts[part]] = True
    all_tri = np.asarray(face.triangles, dtype=np.int64)
    split = chosen[all_tri].all(axis=1)
    tri = all_tri[split]
    edges = np.sort(np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    mid = n + inverse.reshape(3, -1).T
    a, b, c = tri.T
    ab, bc, ca = mid.T
    triangles = np.concatenate([
        all_tri[~split],
        np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1), np.stack([ab, bc, ca], 1),
    ]).astype(np.int32)
    vertices = np.vstack([face.vertices, face.vertices[unique].mean(axis=1)])
    colors = None if face.colors is None else np.vstack([face.colors, face.colors[unique].mean(axis=1)])
    parts = {}
    for name, verts in face.parts.items():
        member = np.zeros(n, dtype=bool)
        member[verts] = True
        parts[name] = np.concatenate([verts, n + np.flatnonzero(member[unique].all(axis=1))]).astype(np.int32)
    lookup = {(int(p), int(q)): n + i for i, (p, q) in enumerate(unique)}
    contours = {name: _refine_loop(loop, lookup) for name, loop in face.contours.items()}
    return Face(
        name=f"{face.name}-subdivided",
        vertices=vertices,
        triangles=triangles,
        parts=parts,
        feature_points=dict(face.feature_points),
        feature_vertices=dict(face.feature_vertices),
        pivots=dict(face.pivots),
        contours=contours,
        colors=colors,
    )


def _refine_loop(loop: np.ndarray, lookup: dict[tuple[int, int], int]) -> np.ndarray:
    """A closed loop with the midpoint of each of its edges inserted (where the edge exists)."""
    out = []
    for p, q in zip(loop, np.roll(loop, -1)):
        out.append(int(p))
        key = (min(int(p), int(q)), max(int(p), int(q)))
        if key in lookup:
            out.append(lookup[key])
    return np.array(out, dtype=np.int32)
