"""Time puppet.sibson.sibson_coordinates on the realistic case: 36,000 queries x 48 sites.

Sites: 40 control points on a mirror-symmetric half-ellipsoid "face" (16 pairs (+-x, y, z) and 8
points on x = 0) plus the 8 corners of the face's bounding box enlarged 1.5x about its centre.
Queries: 36,000 points on or near the surface, 2% of them exactly on x = 0.
Prints the median wall time (triangulation included) over several runs.

    .venv/bin/python tools/bench_sibson.py [runs]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from puppet import sibson

SEMI_AXES = np.array([0.8, 1.0, 0.6])


def surface(u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Front half of the ellipsoid, parametrised by the unit disk (u, w)."""
    z = np.sqrt(np.clip(1.0 - u**2 - w**2, 0.0, None))
    return np.stack([u, w, z], axis=1) * SEMI_AXES


def face_layout(rng: np.random.Generator, n_queries: int = 36_000) -> tuple[np.ndarray, np.ndarray]:
    """(queries, sites) for the realistic layout described in the module docstring."""
    r = 0.85 * np.sqrt(rng.uniform(0.0, 1.0, 16))
    phi = rng.uniform(-0.5 * np.pi, 0.5 * np.pi, 16)
    half = surface(np.abs(r * np.cos(phi)) + 0.05, r * np.sin(phi))
    mirror = half * [-1.0, 1.0, 1.0]
    mid = surface(np.zeros(8), np.linspace(-0.8, 0.8, 8))
    controls = np.vstack([half, mirror, mid])
    r = 0.95 * np.sqrt(rng.uniform(0.0, 1.0, n_queries))
    phi = rng.uniform(0.0, 2.0 * np.pi, n_queries)
    u, w = r * np.cos(phi), r * np.sin(phi)
    u[: n_queries // 50] = 0.0
    queries = surface(u, w) + rng.normal(0.0, 0.01, (n_queries, 3))
    queries[: n_queries // 50, 0] = 0.0
    lo, hi = -SEMI_AXES * [1.0, 1.0, 0.0], SEMI_AXES
    centre, half_size = 0.5 * (lo + hi), 0.75 * (hi - lo)
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
    corners = centre + half_size * signs
    return queries, np.vstack([controls, corners])


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 7
    queries, sites = face_layout(np.random.default_rng(1))
    times = []
    for _ in range(runs):
        sibson._triangulate.cache_clear()
        t0 = time.perf_counter()
        x = sibson.sibson_coordinates(queries, sites)
        times.append(time.perf_counter() - t0)
    err = np.abs(x @ sites - queries).max()
    print(f"{len(queries)} queries x {len(sites)} sites: median {np.median(times):.3f} s "
          f"(min {min(times):.3f}); nnz/row {x.nnz / len(queries):.1f}; linear precision {err:.1e}")


if __name__ == "__main__":
    main()
