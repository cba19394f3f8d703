"""Per-frame vertex normals of a triangle mesh as one sparse product.

A vertex normal is the sum of its triangles' area-weighted normals (the un-normalised cross
product), normalised. The vertex-triangle incidence never changes while a face deforms, so it is
built once as a sparse matrix; each frame is then one cross product per triangle and one sparse
product, with no Python loop and no allocation beyond reusable buffers.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class VertexNormals:
    """Callable that maps vertex positions (N, 3) to unit vertex normals (N, 3)."""

    def __init__(self, triangles: np.ndarray, n_vertices: int) -> None:
        tri = np.asarray(triangles, dtype=np.int64)
        n_tri = len(tri)
        rows = tri.ravel()
        cols = np.repeat(np.arange(n_tri), 3)
        self.triangles = tri
        self.incidence = sp.csr_matrix(
            (np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_tri)
        )
        self._face_normals = np.empty((n_tri, 3))
        self._edge1 = np.empty((n_tri, 3))
        self._edge2 = np.empty((n_tri, 3))

    def __call__(self, vertices: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        tri = self.triangles
        np.subtract(vertices[tri[:, 1]], vertices[tri[:, 0]], out=self._edge1)
        np.subtract(vertices[tri[:, 2]], vertices[tri[:, 0]], out=self._edge2)
        _cross(self._edge1, self._edge2, self._face_normals)
        normals = self.incidence @ self._face_normals
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        np.maximum(length, 1e-30, out=length)
        if out is None:
            return normals / length
        np.divide(normals, length, out=out)
        return out


def _cross(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """Row-wise cross product into ``out`` (np.cross allocates and takes no ``out``)."""
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
