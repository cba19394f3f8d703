"""The face model: a triangle mesh in the MPEG-4 face frame, its parts, feature points and pivots.

A :class:`Face` is what the rest of the rig works on. Its vertex order is the order of the mesh
file (landmark tables and vertex groups index into it), so every loader here keeps it:

* ``load_face()`` returns the embedded default face, a head cut from the MakeHuman hm08 base mesh
  (CC0) by ``tools/build_default_face.py``: skin, eyeballs, teeth and tongue, with all 84 MPEG-4
  feature points (FDP, ISO/IEC 14496-2 Annex C), pivots, lip and lid contours and an albedo per
  vertex. Its data files are ``puppet/data/default_face.npz`` (arrays) and
  ``puppet/data/default_face.json`` (the human-readable tables); ``PROVENANCE.md`` beside them
  says where it comes from and what was changed.
* ``load_face(path)`` reads any mesh trimesh reads. OBJ files are parsed here, in file order (a
  loader that splits vertices at UV seams would renumber them); polygons are fan-triangulated.
  Other formats go through trimesh with ``process=False``; the geometries of a scene are merged
  in order. Such a face has one part, ``skin``, and no feature points; ``load_face(path,
  landmarks=...)`` gives it all of them (``puppet.face.landmarks``), so ``autorig.build_rig`` rigs it.
* ``load_default_rig()`` returns the default face's rig: the shipped ``default_rig.json`` when
  there is one, else the one ``puppet.face.autorig`` generates from the feature points.

Face frame: +x the face's own left, +y up, +z forward (out of the face); units as in the file
(the default face is in decimetres). FAPU (``Face.fapu``) make motion unit-free.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.resources
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from puppet.errors import PuppetError

__all__ = ["Face", "FaceFileError", "MissingFeaturePointsError", "load_face", "load_default_rig"]

DEFAULT_NAME = "default"
DEFAULT_NPZ = "default_face.npz"
DEFAULT_JSON = "default_face.json"
DEFAULT_RIG = "default_rig.json"

# FAPU (ISO/IEC 14496-2 Annex C): name -> (feature point a, feature point b, axis); the unit is
# (a[axis] - b[axis]) / 1024 measured on the neutral face.
FAPU_DEFINITIONS = {
    "IRISD0": ("3.1", "3.3", 1),
    "ES0": ("3.5", "3.6", 0),
    "ENS0": ("3.5", "9.15", 1),
    "MNS0": ("9.15", "2.2", 1),
    "MW0": ("8.3", "8.4", 0),
}
AU = 1e-5  # angle unit, radians


class FaceFileError(PuppetError, ValueError):
    """A mesh file that cannot be read as a face; the message names the file and the problem."""


class MissingFeaturePointsError(PuppetError, LookupError):
    """The face lacks feature points that a computation needs; ``missing`` lists their ids."""

    def __init__(self, face_name: str, what: str, missing: list[str]) -> None:
        self.missing = list(missing)
        super().__init__(f"face {face_name!r} has no feature point(s) {', '.join(self.missing)} "
                         f"needed for {what}")


@dataclass
class Face:
    """A face mesh in the MPEG-4 face frame (+x the face's left, +y up, +z forward)."""

    name: str
    vertices: np.ndarray  # (N, 3) float64 rest positions
    triangles: np.ndarray  # (F, 3) int32
    parts: dict[str, np.ndarray]  # part name -> sorted int32 vertex indices
    feature_points: dict[str, np.ndarray] = field(default_factory=dict)  # FDP id -> xyz
    feature_vertices: dict[str, int] = field(default_factory=dict)  # FDP id -> vertex (on-vertex ones)
    pivots: dict[str, np.ndarray] = field(default_factory=dict)  # eye_l, eye_r, jaw, head; jaw_axis
    contours: dict[str, np.ndarray] = field(default_factory=dict)  # name -> closed vertex loop
    colors: np.ndarray | None = None  # (N, 3) float32 albedo in 0..1
    uv: np.ndarray | None = None  # (T, 2) float32
    triangle_uv: np.ndarray | None = None  # (F, 3) int32 rows of uv per triangle corner
    source_index: np.ndarray | None = None  # (N,) int32 vertex index in the source mesh, -1 generated
    frame: np.ndarray | None = None  # 3x4 [R | t] that took the file's coordinates into the face frame

    @property
    def fapu(self) -> dict[str, float]:
        """The face animation parameter units of this (neutral) face: IRISD0, ES0, ENS0, MNS0,
        MW0 (each a distance between feature points / 1024, in mesh units) and AU (1e-5 rad)."""
        needed = sorted({p for a, b, _ in FAPU_DEFINITIONS.values() for p in (a, b)},
                        key=_fdp_sort_key)
        missing = [p for p in needed if p not in self.feature_points]
        if missing:
            raise MissingFeaturePointsError(self.name, "FAPU", missing)
        units = {}
        for unit, (a, b, axis) in FAPU_DEFINITIONS.items():
            units[unit] = float(self.feature_points[a][axis] - self.feature_points[b][axis]) / 1024.0
        units["AU"] = AU
        return units

    @property
    def content_hash(self) -> str:
        """sha256 (hex) of the rest vertices (float64) and triangles (int32): a cache key.

        Computed on every call (about 1 ms per 50,000 vertices), never cached: the arrays can be
        edited in place, and a stale hash would key the coefficient cache on disk to another mesh."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.vertices, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(self.triangles, dtype="<i4").tobytes())
        return h.hexdigest()


def load_face(path: str | os.PathLike | None = None, landmarks=None) -> Face:
    """The embedded default face (``path`` None), or the mesh at ``path`` in file vertex order.

    ``landmarks`` (a JSON path, a dict {FDP id: vertex} or a list of 68 iBUG vertices) makes the
    mesh rig-ready: face frame, parts, contours, pivots and feature points (``puppet.face.landmarks``).
    A folder is a face folder (``puppet.face.folder``: a face built from a photo, textured).
    """
    if path is None:
        return _load_default()
    if Path(path).is_dir():
        from puppet.face.folder import load_face_folder

        return load_face_folder(path)
    face = _load_mesh(path)
    if landmarks is None:
        return face
    from puppet.face.landmarks import apply_landmarks

    return apply_landmarks(face, landmarks)


def _load_mesh(path: str | os.PathLike) -> Face:
    """The mesh at ``path`` as a one-part face without feature points."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"face mesh {str(path)!r} does not exist")
    if not path.is_file():
        raise FaceFileError(f"face mesh {str(path)!r} is not a file")
    if path.suffix.lower() == ".obj":
        mesh = read_obj(path)
        positions, triangles, tri_uv = mesh.triangulated()
        uv = mesh.uvs.astype(np.float32) if tri_uv is not None else None
        colors = mesh.colors
    else:
        positions, triangles, uv, tri_uv, colors = _read_with_trimesh(path)
    if len(triangles) == 0:
        raise FaceFileError(f"face mesh {str(path)!r} has no faces")
    return Face(
        name=path.stem,
        vertices=positions,
        triangles=triangles,
        parts={"skin": np.arange(len(positions), dtype=np.int32)},
        colors=colors,
        uv=uv,
        triangle_uv=tri_uv,
    )


def load_default_rig(generate: bool = True):
    """The default face's rig: ``puppet/data/default_rig.json`` when it is shipped, else the rig
    ``puppet.face.autorig`` generates from the default face's feature points (None if not ``generate``)."""
    from puppet.face import autorig, rig

    resource = _data_file(DEFAULT_RIG)
    if resource.is_file():
        with importlib.resources.as_file(resource) as p:
            return rig.load_rig(p)
    return autorig.build_rig(load_face()) if generate else None


# -- the default face ------------------------------------------------------------------------

def _load_default() -> Face:
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


# -- OBJ in file order -------------------------------------------------------------------------

@dataclass
class ObjMesh:
    """An OBJ file as written: vertices and polygons in file order (0-based indices)."""

    positions: np.ndarray  # (N, 3) float64
    uvs: np.ndarray  # (T, 2) float64
    polygons: list[list[int]]  # vertex indices per polygon
    polygon_uvs: list[list[int] | None]  # uv indices per polygon corner, None where it has none
    groups: list[str | None]  # the 'g' group each polygon was in
    colors: np.ndarray | None = None  # (N, 3) float32 when every 'v' line carries r g b

    def triangulated(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(positions, triangles (F, 3) int32, triangle_uv (F, 3) int32 or None): polygons
        fan-triangulated from their first corner, so a quad a b c d gives a b c and a c d."""
        tris, tri_uv = [], []
        has_uv = all(p is not None for p in self.polygon_uvs) and len(self.uvs) > 0
        for poly, puv in zip(self.polygons, self.polygon_uvs):
            for k in range(1, len(poly) - 1):
                tris.append((poly[0], poly[k], poly[k + 1]))
                if has_uv:
                    tri_uv.append((puv[0], puv[k], puv[k + 1]))
        triangles = np.array(tris, dtype=np.int32).reshape(-1, 3)
        uv = np.array(tri_uv, dtype=np.int32).reshape(-1, 3) if has_uv else None
        return self.positions, triangles, uv


def read_obj(path: str | os.PathLike) -> ObjMesh:
    """Parse an OBJ file's v, vt, f (and g) lines in file order; normals and materials are
    ignored. Indices may be negative (relative). Errors name the file and line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise FaceFileError(f"cannot read face mesh {str(path)!r}: {exc.strerror or exc}") from exc
    positions: list[list[float]] = []
    colors: list[list[float]] = []
    uvs: list[list[float]] = []
    polygons: list[list[int]] = []
    polygon_uvs: list[list[int] | None] = []
    groups: list[str | None] = []
    group = None
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        tag = parts[0]
        try:
            if tag == "v":
                values = [float(x) for x in parts[1:]]
                if len(values) < 3:
                    raise ValueError("a vertex needs x y z")
                positions.append(values[:3])
                if len(values) >= 6:  # the common "v x y z r g b" extension
                    colors.append(values[3:6])
            elif tag == "vt":
                values = [float(x) for x in parts[1:3]]
                if not values:
                    raise ValueError("a texture coordinate needs u")
                uvs.append(values + [0.0] * (2 - len(values)))
            elif tag == "f":
                corners = parts[1:]
                if len(corners) < 3:
                    raise ValueError(f"a face needs 3 or more corners, got {len(corners)}")
                vi, ti = [], []
                for corner in corners:
                    fields = corner.split("/")
                    vi.append(_obj_index(fields[0], len(positions), "vertex"))
                    if len(fields) > 1 and fields[1]:
                        ti.append(_obj_index(fields[1], len(uvs), "texture coordinate"))
                polygons.append(vi)
                polygon_uvs.append(ti if len(ti) == len(vi) else None)
                groups.append(group)
            elif tag == "g":
                group = " ".join(parts[1:]) or None
        except ValueError as exc:
            raise FaceFileError(f"{path}:{lineno}: {exc}: {line.strip()[:80]!r}") from None
    if not positions:
        raise FaceFileError(f"face mesh {str(path)!r} has no vertices ('v' lines)")
    color_array = None
    if colors and len(colors) == len(positions):
        c = np.array(colors, dtype=np.float32)
        color_array = c / 255.0 if c.max(initial=0.0) > 1.0 else c
    return ObjMesh(
        positions=np.array(positions, dtype=np.float64),
        uvs=np.array(uvs, dtype=np.float64).reshape(-1, 2),
        polygons=polygons,
        polygon_uvs=polygon_uvs,
        groups=groups,
        colors=color_array,
    )


def _obj_index(token: str, count: int, what: str) -> int:
    """A 1-based (or negative, relative) OBJ index as a 0-based index, checked against count."""
    i = int(token)
    if i == 0:
        raise ValueError(f"{what} index 0 (OBJ indices start at 1)")
    j = i - 1 if i > 0 else count + i
    if not 0 <= j < count:
        raise ValueError(f"{what} index {i} out of range (only {count} defined so far)")
    return j


# -- other formats through trimesh ---------------------------------------------------------------

def _read_with_trimesh(path: Path):
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False, maintain_order=True)
    except Exception as exc:  # trimesh raises many kinds; name the file either way
        raise FaceFileError(f"cannot read face mesh {str(path)!r}: {type(exc).__name__}: {exc}") from exc
    if isinstance(loaded, trimesh.Scene):
        meshes = _scene_meshes(loaded)
    else:
        meshes = [loaded]
    meshes = [m for m in meshes if isinstance(m, trimesh.Trimesh)]
    if not meshes:
        raise FaceFileError(f"face mesh {str(path)!r} holds no triangle mesh")
    positions, triangles, uvs, colors = [], [], [], []
    offset = 0
    for m in meshes:
        positions.append(np.asarray(m.vertices, dtype=np.float64))
        triangles.append(np.asarray(m.faces, dtype=np.int64) + offset)
        offset += len(m.vertices)
        visual = getattr(m, "visual", None)
        uv = getattr(visual, "uv", None) if visual is not None and visual.kind == "texture" else None
        uvs.append(None if uv is None or len(uv) != len(m.vertices) else np.asarray(uv, np.float32))
        vc = None
        if visual is not None and visual.kind == "vertex":
            vc = np.asarray(visual.vertex_colors, dtype=np.float32)[:, :3] / 255.0
        colors.append(vc)
    vertices = np.vstack(positions)
    tris = np.vstack(triangles).astype(np.int32)
    uv = np.vstack(uvs).astype(np.float32) if all(u is not None for u in uvs) else None
    tri_uv = tris.copy() if uv is not None else None
    color = np.vstack(colors).astype(np.float32) if all(c is not None for c in colors) else None
    return vertices, tris, uv, tri_uv, color


def _scene_meshes(scene) -> list:
    """The scene's geometries in file order, each placed by the node transform(s) that use it."""
    out = []
    for name, geometry in scene.geometry.items():
        nodes = scene.graph.geometry_nodes.get(name, [])
        if not nodes:
            out.append(geometry)
        for node in nodes:
            transform, _ = scene.graph[node]
            placed = geometry.copy()
            placed.apply_transform(transform)
            out.append(placed)
    return out


def _fdp_sort_key(fid: str) -> tuple[int, int]:
    group, index = fid.split(".")
    return int(group), int(index)
