"""The embedded default face and its shipped rig.

The default face is a head cut from the MakeHuman hm08 base mesh (CC0) by
``tools/builders/build_default_face.py``: skin, eyeballs, teeth and tongue, with all 84 MPEG-4 feature
points (FDP, ISO/IEC 14496-2 Annex C), pivots, lip and lid contours and an albedo per vertex. Its
data files are ``puppet/data/default_face.npz`` (arrays) and ``puppet/data/default_face.json``
(the human-readable tables); ``PROVENANCE.md`` beside them says where it comes from and what was
changed. Its rig, ``puppet/data/default_rig.json``, is what ``tools/builders/build_default_rig.py`` makes of
it with ``puppet.face.autorig`` and the calibration.
"""

from __future__ import annotations

import functools
import importlib.resources
import io
import json

import numpy as np

from puppet.face.model import Face
from puppet.face.rig import Rig, load_rig

DEFAULT_NAME = "default"
DEFAULT_NPZ = "default_face.npz"
DEFAULT_JSON = "default_face.json"
DEFAULT_RIG = "default_rig.json"
DEFAULT_UNIT_MM = 100.0
"""The default face's unit in millimetres: MakeHuman's decimetre (the head is 2.9 units tall)."""


def default_face() -> Face:
    """A fresh, writable copy of the embedded default face."""
    data = _default_arrays()
    meta = _default_meta()
    arrays = {k: v.copy() for k, v in data.items()}  # a fresh, writable copy for every caller
    parts = {k[len("part_"):]: arrays[k] for k in sorted(arrays) if k.startswith("part_")}
    feature_points, feature_vertices = {}, {}
    for fid, entry in meta["feature_points"].items():
        feature_points[fid] = np.array(entry["xyz"], dtype=np.float64)
        if entry.get("index") is not None:
            feature_vertices[fid] = int(entry["index"])
            feature_points[fid] = arrays["vertices"][entry["index"]].copy()
    pivots = {k: np.array(v["xyz"] if isinstance(v, dict) else v, dtype=np.float64)
              for k, v in meta["pivots"].items()}
    contours = {k: np.array(v["indices"], dtype=np.int32) for k, v in meta["contours"].items()}
    return Face(
        name=DEFAULT_NAME,
        vertices=arrays["vertices"],
        triangles=arrays["triangles"],
        parts=parts,
        feature_points=feature_points,
        feature_vertices=feature_vertices,
        pivots=pivots,
        contours=contours,
        colors=arrays.get("colors"),
        uv=arrays.get("uv"),
        triangle_uv=arrays.get("triangle_uv"),
        source_index=arrays.get("source_index"),
    )


def _data_file(name: str):
    """A file of the packaged data folder (puppet/data) as an importlib.resources Traversable."""
    return importlib.resources.files("puppet").joinpath("data").joinpath(name)


@functools.lru_cache(maxsize=1)
def _default_arrays() -> dict[str, np.ndarray]:
    raw = _data_file(DEFAULT_NPZ).read_bytes()
    with np.load(io.BytesIO(raw), allow_pickle=False) as npz:
        return {k: npz[k] for k in npz.files}


@functools.lru_cache(maxsize=1)
def _default_meta() -> dict:
    return json.loads(_data_file(DEFAULT_JSON).read_text("utf-8"))




def load_default_rig() -> Rig | None:
    """The default face's shipped rig (``puppet/data/default_rig.json``), or None when the package
    ships none (while ``tools/builders/build_default_rig.py`` makes it)."""
    resource = _data_file(DEFAULT_RIG)
    if not resource.is_file():
        return None
    with importlib.resources.as_file(resource) as path:
        return load_rig(path)
