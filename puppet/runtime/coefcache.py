"""On-disk cache of a rig's Sibson coordinate matrices ("non-real-time" mode of the paper).

Sibson coordinates depend only on the rest mesh and the rig, so they are computed once and kept
in ``$FACEPUPPET_CACHE`` (default ``~/.cache/facepuppet``) under a key hashed from the mesh, the
rig, the format version and the source of the modules that define and compute them: a changed
face, rig or algorithm can never load stale coefficients. A corrupt or
unreadable cache file is ignored and recomputed, and an unwritable cache folder only warns:
neither is ever an error.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse as sp

CACHE_FORMAT = 1


def cache_dir() -> Path:
    """Where coefficient files live; created on first use."""
    root = os.environ.get("FACEPUPPET_CACHE") or Path.home() / ".cache" / "facepuppet"
    return Path(root)


def cache_key(mesh_hash: str, rig_dict: dict) -> str:
    """A stable key for one mesh + rig + cache format + the code that computes coefficients."""
    text = json.dumps({"mesh": mesh_hash, "rig": rig_dict, "format": CACHE_FORMAT}, sort_keys=True)
    digest = hashlib.sha256(text.encode())
    for module in ("sibson.py", "dffd.py", "runtime.py"):
        digest.update(Path(__file__).with_name(module).read_bytes())
    return digest.hexdigest()[:32]


def load(key: str) -> dict[str, tuple[np.ndarray, sp.csr_matrix]] | None:
    """Region name -> (box corners, Sibson matrix), or None when absent or unreadable."""
    path = cache_dir() / f"{key}.npz"
    try:
        with np.load(path) as data:
            names = [str(n) for n in data["regions"]]
            return {
                name: (
                    data[f"{name}.box"],
                    sp.csr_matrix(
                        (data[f"{name}.data"], data[f"{name}.indices"], data[f"{name}.indptr"]),
                        shape=tuple(data[f"{name}.shape"]),
                    ),
                )
                for name in names
            }
    except Exception:  # a cache is only ever a shortcut: any damage means "compute again"
        return None


def store(key: str, regions: dict[str, tuple[np.ndarray, sp.csr_matrix]]) -> None:
    """Write atomically (temp file + rename) so a crash never leaves a half-written cache."""
    arrays: dict[str, np.ndarray] = {"regions": np.array(list(regions))}
    for name, (box, matrix) in regions.items():
        arrays[f"{name}.box"] = box
        arrays[f"{name}.data"] = matrix.data
        arrays[f"{name}.indices"] = matrix.indices
        arrays[f"{name}.indptr"] = matrix.indptr
        arrays[f"{name}.shape"] = np.array(matrix.shape)
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, suffix=".tmp", delete=False) as tmp:
            try:
                np.savez(tmp, **arrays)
            except BaseException:
                os.unlink(tmp.name)
                raise
        os.replace(tmp.name, folder / f"{key}.npz")
    except OSError as exc:
        warnings.warn(f"coefficient cache not written to {folder} ({exc}); the rig will be recomputed next time",
                      stacklevel=2)
