"""Time puppet.runtime.sibson.sibson_coordinates on the realistic case: 36,000 queries x 48 sites.

Sites: 40 control points on a mirror-symmetric half-ellipsoid "face" (16 pairs (+-x, y, z) and 8
points on x = 0) plus the 8 corners of the face's bounding box enlarged 1.5x about its centre.
Queries: 36,000 points on or near the surface, 2% of them exactly on x = 0.
Prints the median wall time (triangulation included) over several runs.

When g++ and CGAL 5.5's headers are installed (``apt-get install libcgal-dev``), the same layout is
also run through CGAL's ``sibson_natural_neighbor_coordinates_3`` (tools/bench/cgal_sibson.cpp, compiled
once into a cache folder under the temp directory), the same number of times, and the script
prints CGAL's median, the ratio CGAL / ours and the largest difference between the two coordinate
matrices.  Without CGAL it says so and reports our timing only.  Both measurements are meant to be
single-threaded (the BLAS thread variables are set to 1 unless already set; pin the process with
``taskset -c 1`` for stable figures).

    .venv/bin/python tools/bench/bench_sibson.py [runs]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
             "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import hashlib  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402

from puppet.runtime import sibson

SEMI_AXES = np.array([0.8, 1.0, 0.6])

CGAL_SOURCE = Path(__file__).with_name("cgal_sibson.cpp")
CGAL_HEADER = Path("/usr/include/CGAL/natural_neighbor_coordinates_3.h")
# Release build as CGAL's own CMake would do it; -frounding-math is required by CGAL's interval
# arithmetic (the exact predicates) under GCC.
CGAL_FLAGS = ["-std=c++17", "-O2", "-DNDEBUG", "-frounding-math"]
CGAL_LIBS = ["-lgmp", "-lmpfr"]
AGREE_TOL = 1e-9


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


def build_cgal() -> Path | None:
    """Path of the compiled CGAL reference program, or None (with a message) if unavailable."""
    gxx = shutil.which("g++")
    if gxx is None or not CGAL_HEADER.exists():
        missing = "g++" if gxx is None else str(CGAL_HEADER)
        print(f"CGAL reference skipped: {missing} not found "
              "(install with: apt-get install libcgal-dev g++)")
        return None
    key = hashlib.sha256(CGAL_SOURCE.read_bytes() + " ".join(CGAL_FLAGS + CGAL_LIBS).encode())
    cache = Path(tempfile.gettempdir()) / "puppet_cgal_sibson"
    exe = cache / f"cgal_sibson_{key.hexdigest()[:16]}"
    if exe.exists():
        return exe
    cache.mkdir(parents=True, exist_ok=True)
    tmp = cache / f"{exe.name}.{os.getpid()}.tmp"
    cmd = [gxx, *CGAL_FLAGS, "-o", str(tmp), str(CGAL_SOURCE), *CGAL_LIBS]
    print("compiling CGAL reference: " + " ".join(cmd), flush=True)
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        print("CGAL reference skipped: compilation failed:\n" + proc.stderr[-3000:])
        tmp.unlink(missing_ok=True)
        return None
    tmp.replace(exe)
    return exe


def run_cgal(exe: Path, queries: np.ndarray, sites: np.ndarray, runs: int
             ) -> tuple[np.ndarray, np.ndarray, int, sp.csr_matrix]:
    """(triangulation seconds, coordinate seconds, failed queries, coordinates) from CGAL."""
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.bin", Path(tmp) / "out.bin"
        header = np.array([len(sites), len(queries)], dtype=np.int64)
        src.write_bytes(header.tobytes()
                        + np.ascontiguousarray(sites, dtype=np.float64).tobytes()
                        + np.ascontiguousarray(queries, dtype=np.float64).tobytes())
        subprocess.run([str(exe), str(src), str(dst), str(runs)], check=True)
        raw = dst.read_bytes()
    n_runs = int(np.frombuffer(raw, np.int64, 1, 0)[0])
    times = np.frombuffer(raw, np.float64, 2 * n_runs, 8)
    failed, nnz = np.frombuffer(raw, np.int64, 2, 8 + 16 * n_runs)
    trip = np.frombuffer(raw, np.float64, 3 * int(nnz), 24 + 16 * n_runs).reshape(-1, 3)
    x = sp.csr_matrix((trip[:, 2], (trip[:, 0].astype(np.int64), trip[:, 1].astype(np.int64))),
                      shape=(len(queries), len(sites)))
    return times[:n_runs], times[n_runs:], int(failed), x


def compare(x: sp.csr_matrix, y: sp.csr_matrix, queries: np.ndarray, sites: np.ndarray,
            err: float) -> None:
    """Print how far CGAL's coordinates y are from ours x (union of both sparsity patterns)."""
    d = abs(x - y).tocsr()
    row_max = d.max(axis=1).toarray().ravel() if d.nnz else np.zeros(x.shape[0])
    diff = float(row_max.max()) if len(row_max) else 0.0
    err_cgal = np.abs(y @ sites - queries).max()
    # Natural neighbours: stored entries of either matrix (ours may store an exact 0 in a tie).
    pattern = (x.astype(bool).astype(np.int8) - y.astype(bool).astype(np.int8)).tocsr()
    pattern.eliminate_zeros()
    stored = abs(sp.csr_matrix((np.ones_like(x.data), x.indices, x.indptr), shape=x.shape)
                 - sp.csr_matrix((np.ones_like(y.data), y.indices, y.indptr), shape=y.shape))
    stored.eliminate_zeros()
    print(f"max |ours - CGAL| {diff:.1e} (worst query {int(np.argmax(row_max))}) = "
          f"{diff / err:.1f}x ours' linear-precision error {err:.1e} (CGAL's {err_cgal:.1e}); "
          f"natural-neighbour sets differ in {stored.nnz} entries, "
          f"{pattern.nnz} entries are zero on one side only")
    bad = np.flatnonzero(row_max > AGREE_TOL)
    if len(bad):
        print(f"DISAGREEMENT: {len(bad)} queries differ by more than {AGREE_TOL:g}; "
              f"first: {bad[:10].tolist()}")


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

    exe = build_cgal()
    if exe is None:
        return
    t_tri, t_coord, failed, y = run_cgal(exe, queries, sites, runs)
    total = t_tri + t_coord
    ours = float(np.median(times))
    cgal = float(np.median(total))
    print(f"CGAL 5.5 sibson_natural_neighbor_coordinates_3: median {cgal:.3f} s "
          f"(min {total.min():.3f}) over {runs} runs; medians: triangulation "
          f"{np.median(t_tri) * 1e3:.2f} ms, coordinates {np.median(t_coord):.3f} s; "
          f"nnz/row {y.nnz / len(queries):.1f}"
          + (f"; {failed} queries rejected as outside the hull" if failed else ""))
    print(f"ratio CGAL / ours: {cgal / ours:.2f} (ours {ours:.3f} s, CGAL {cgal:.3f} s)")
    compare(x, y, queries, sites, err)


if __name__ == "__main__":
    main()
