"""Skin smoothing: the motion of a few skin vertices averaged with their neighbours', where a face
rigged by transfer would crease.

DFFD moves each vertex by the Sibson coordinates of its region's control points. They are smooth
between control points but only continuous at the points themselves and across region
boundaries. Where neighbouring control points move differently, the skin hinges round a point or
along a line: a crease (``puppet.runtime.creases``). A face rigged by transfer has many such points
(``puppet.face.autorig``'s skin grid, each carrying motions transferred from the default face), and
its finer mesh shows each hinge on one short edge.

The rig's ``smoothed`` vertices (``puppet.face.rig``) take, ``PASSES`` times over, the mean of their
own motion and their neighbours' along the skin's edges; the others keep theirs. That is linear
in the motion, so the runtime folds it into B (``smoothing_matrix @ B``): no step is added to a
frame, only entries to B's smoothed rows (on ICT, 2.3 times B's entries and about 0.5 ms more a
frame). Rest stays rest, a translation stays a translation, and a vertex that is not listed moves
exactly as before. Which vertices are listed is found where the poses crease
(``puppet.runtime.creasesmoothing``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

PASSES = 4
"""Times the listed vertices take their neighbourhood's mean motion: enough to spread a hinge over
the two or three rings around it, few enough to keep the motion's shape (more passes flattened
ICT's cheeks and folded more triangles than they unfolded)."""


def skin_triangles(face) -> np.ndarray:
    """The triangles whose three corners are on the skin part (every triangle if it has none)."""
    tri = np.asarray(face.triangles)
    if "skin" not in face.parts:
        return tri
    on = np.zeros(len(face.vertices), dtype=bool)
    on[face.parts["skin"]] = True
    return tri[on[tri].all(axis=1)]


def neighbours(triangles: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """The symmetric vertex adjacency (n, n) of a triangle mesh: 1 where two vertices share an edge."""
    tri = np.asarray(triangles, dtype=np.int64)
    rows = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2], tri[:, 1], tri[:, 2], tri[:, 0]])
    cols = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0], tri[:, 0], tri[:, 1], tri[:, 2]])
    adjacency = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_vertices))
    adjacency.data[:] = 1.0
    return adjacency


def grown(vertices: np.ndarray, adjacency: sp.csr_matrix, rings: int) -> np.ndarray:
    """Bool mask of ``vertices`` (a bool mask) and the ``rings`` rings of neighbours around them."""
    mask = np.asarray(vertices, dtype=bool).copy()
    for _ in range(rings):
        mask |= adjacency @ mask.astype(float) > 0
    return mask


def smoothing_matrix(triangles: np.ndarray, n_vertices: int, smoothed: np.ndarray,
                     passes: int = PASSES) -> sp.csr_matrix:
    """The matrix S (n, n) that smooths a motion field (n, 3) as the module says: S @ D. Rows of
    vertices not in ``smoothed`` are the identity's. ``triangles``: the skin's, so the mean never
    reaches across to the eyes or teeth."""
    adjacency = neighbours(triangles, n_vertices)
    listed = np.zeros(n_vertices, dtype=bool)
    listed[np.asarray(smoothed, dtype=np.int64)] = True
    mean = sp.diags(1.0 / (1.0 + np.asarray(adjacency.sum(axis=1)).ravel())) @ (adjacency + sp.identity(n_vertices))
    step = sp.csr_matrix(sp.diags((~listed).astype(float)) + sp.diags(listed.astype(float)) @ mean)
    out = sp.identity(n_vertices, format="csr")
    for _ in range(passes):
        out = sp.csr_matrix(step @ out)
    return out
