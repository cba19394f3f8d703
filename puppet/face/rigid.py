"""Rigid motions of the face's parts as 3x4 matrices [R | t]: x' = R x + t."""

from __future__ import annotations

import math

import numpy as np

IDENTITY = np.hstack([np.eye(3), np.zeros((3, 1))])
IDENTITY.setflags(write=False)


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """3x3 rotation by ``angle`` radians about the unit vector ``axis`` (right-hand rule)."""
    return np.array(_rotation_rows(tuple(float(v) for v in axis), angle))


def turn(pivot: tuple[float, float, float], axis: tuple[float, float, float], angle: float,
         shift: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """``about(pivot, rotation(axis, angle), shift)``: the turn by ``angle`` radians about the line
    through ``pivot`` along ``axis``, then the shift. Scalar math on Python floats, one array made:
    the jaw's and the lids' motions are made again every frame they move."""
    px, py, pz = pivot
    return np.array([(a, b, c, p - (a * px + b * py + c * pz) + t)
                     for (a, b, c), p, t in zip(_rotation_rows(axis, angle), pivot, shift)])


def _rotation_rows(axis: tuple[float, float, float], angle: float) -> tuple[tuple[float, ...], ...]:
    """The rows of ``rotation``, in scalar math (numpy's calls on 3x3 arrays cost more than the
    arithmetic, and motions are made a dozen times a frame)."""
    x, y, z = axis
    n = math.sqrt(x * x + y * y + z * z)
    x, y, z = x / n, y / n, z / n
    c, s = math.cos(angle), math.sin(angle)
    C = 1.0 - c
    return ((c + x * x * C, x * y * C - z * s, x * z * C + y * s),
            (y * x * C + z * s, c + y * y * C, y * z * C - x * s),
            (z * x * C - y * s, z * y * C + x * s, c + z * z * C))


def about(pivot: np.ndarray, R: np.ndarray, translation: np.ndarray | None = None) -> np.ndarray:
    """Motion rotating by R about ``pivot``, then translating: x' = R (x - pivot) + pivot + t."""
    pivot = np.asarray(pivot, dtype=float)
    motion = np.empty((3, 4))
    motion[:, :3] = R
    motion[:, 3] = pivot - R @ pivot
    if translation is not None:
        motion[:, 3] += translation
    return motion


def apply(motion: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The points moved by a 3x4 motion."""
    return points @ motion[:, :3].T + motion[:, 3]


def compose(outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """The motion doing ``inner`` first, then ``outer``."""
    R = outer[:, :3] @ inner[:, :3]
    return np.hstack([R, (outer[:, :3] @ inner[:, 3] + outer[:, 3])[:, None]])


def kabsch(rest: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """The rigid motion that best maps ``rest`` points onto ``moved`` ones (least squares)."""
    a, b = rest.mean(axis=0), moved.mean(axis=0)
    u, _, vt = np.linalg.svd((rest - a).T @ (moved - b))
    flip = np.sign(np.linalg.det(vt.T @ u.T))
    R = vt.T @ np.diag([1.0, 1.0, flip]) @ u.T
    return np.hstack([R, (b - R @ a)[:, None]])
