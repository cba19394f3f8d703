"""A face folder: a face ready for ``--face``, written so that any OBJ viewer shows it and
facepuppet loads and animates it like the default face. Two commands write one: ``puppet
face-from-photo`` (a face built from a photo, ``puppet.photo.build``: textured) and ``puppet rig
MESH --landmarks ... -o FOLDER/`` (any mesh, rigged from its landmarks: with the colours and
texture its file gave it, its parts as the file's pieces named them).

Files:

* ``face.obj``: ``v x y z r g b`` (vertex colours: the fall-back colours; plain ``v x y z`` when
  the mesh has none) and triangles in the face's vertex order; a textured face adds ``vt`` one per
  vertex (``f a/a b/b c/c``) and ``face.mtl``, which names the texture;
* ``texture.png`` (textured faces only): the photo cut to the head, or the base-colour textures of
  a mesh file's pieces in one atlas (``puppet.face.atlas``);
* ``face.json``: what an OBJ cannot say: parts, feature points (FDP id -> xyz and vertex),
  pivots, contours, the placement that turned a mesh file into the face frame (so its morph
  targets turn alike, ``puppet.face.examples``), where the face came from, and for a textured
  face the per-vertex texture weight (how much of the texture shows over the vertex colour; see
  ``puppet.view.renderer``) and the fit's report;
* ``face.rig``: the auto-rig's rig of the face (``puppet.face.rig.save_rig``).
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path

import numpy as np
from PIL import Image

from puppet.face.meshfile import obj_lines, read_obj
from puppet.face.model import Face, FaceFileError, TexturedFace
from puppet.face.rig import load_rig, save_rig

FACE_OBJ = "face.obj"
FACE_MTL = "face.mtl"
FACE_TEXTURE = "texture.png"
FACE_JSON = "face.json"
FACE_RIG = "face.rig"
FORMAT = "facepuppet-face-folder"


def write_face_folder(face: TexturedFace, out: str | os.PathLike, *, source_photo: str,
                      report: dict) -> Path:
    """Write the textured ``face`` into the folder ``out`` (created) as face.obj, face.mtl,
    texture.png and face.json; return the folder."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / FACE_OBJ).write_text(_obj_text(face, f"a face from a photo ({face.name}): the MakeHuman hm08 "
                                                   "default face (CC0) warped"), encoding="utf-8")
    _write_texture(folder, face)
    meta = _meta(face, source_photo=source_photo, texture_weight=np.round(face.texture_weight, 4).tolist(),
                 fit=report)
    (folder / FACE_JSON).write_text(json.dumps(meta), encoding="utf-8")
    return folder


def write_rigged_folder(face: Face, rig, out: str | os.PathLike, *, source_mesh: str) -> Path:
    """Write a rigged ``face`` (a mesh given its landmarks) and its ``rig`` into the folder ``out``
    (created) as face.obj, face.json and face.rig, and when the face is textured (a GLB's base
    colour textures, an OBJ's map_Kd) face.mtl and texture.png too; return the folder."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / FACE_OBJ).write_text(_obj_text(face, f"{face.name}, rigged from {Path(source_mesh).name}"),
                                   encoding="utf-8")
    extra = {}
    if getattr(face, "texture", None) is not None:
        _write_texture(folder, face)
        extra["texture_weight"] = np.round(np.asarray(face.texture_weight, dtype=float), 4).tolist()
    else:  # a texture left from an earlier face in this folder is not this face's
        for stale in (FACE_MTL, FACE_TEXTURE):
            (folder / stale).unlink(missing_ok=True)
    (folder / FACE_JSON).write_text(json.dumps(_meta(face, source_mesh=source_mesh, **extra)), encoding="utf-8")
    save_rig(rig, folder / FACE_RIG)
    return folder


def _write_texture(folder: Path, face: TexturedFace) -> None:
    """face.mtl naming texture.png, and texture.png."""
    (folder / FACE_MTL).write_text(f"newmtl face\nKd 1 1 1\nmap_Kd {FACE_TEXTURE}\n", encoding="utf-8")
    Image.fromarray(np.asarray(face.texture, dtype=np.uint8)).save(folder / FACE_TEXTURE, format="PNG")


def _meta(face: Face, **extra) -> dict:
    """face.json: the face's parts, feature points, pivots, contours and placement, and ``extra``."""
    placement = {} if face.placement is None else {"placement": np.asarray(face.placement, float).tolist()}
    return {
        "format": FORMAT, "version": 1, "name": face.name,
        "parts": {k: v.tolist() for k, v in face.parts.items()},
        "feature_points": {k: {"xyz": [round(float(c), 7) for c in p], "index": face.feature_vertices.get(k)}
                           for k, p in face.feature_points.items()},
        "pivots": {k: [float(c) for c in p] for k, p in face.pivots.items()},
        "contours": {k: v.tolist() for k, v in face.contours.items()},
        **placement,
        **extra,
    }


def _obj_text(face: Face, title: str) -> str:
    """The OBJ file: header, then coloured vertices and triangles; with a texture, the material,
    per-vertex uv and v/vt triangles. Positions are written to the last bit (``%.17g``), so the
    folder reads back the very mesh its rig was made for (``Rig.face_hash``): rounded, the saved
    rig was passed over and a new one built at every load."""
    textured = getattr(face, "texture", None) is not None
    out = io.StringIO()
    out.write(f"# facepuppet face folder: {title}\n")
    if textured:
        out.write(f"mtllib {FACE_MTL}\nusemtl face\n")
    if face.colors is not None:
        out.write(obj_lines("v %.17g %.17g %.17g %.4f %.4f %.4f", np.c_[face.vertices, face.colors]))
    else:
        out.write(obj_lines("v %.17g %.17g %.17g", face.vertices))
    t = np.asarray(face.triangles, dtype=np.int64) + 1
    if textured:
        out.write(obj_lines("vt %.6f %.6f", face.uv))
        out.write(obj_lines("f %d/%d %d/%d %d/%d", np.repeat(t, 2, axis=1)))
    else:
        out.write(obj_lines("f %d %d %d", t))
    return out.getvalue()


def load_face_folder(path: str | os.PathLike) -> TexturedFace:
    """The face in a face folder (module docstring); errors name the folder and the file."""
    folder = Path(path)
    for name in (FACE_OBJ, FACE_JSON):
        if not (folder / name).is_file():
            raise FaceFileError(f"face folder {str(folder)!r} has no {name} (make one with `puppet rig MESH "
                                f"--landmarks POINTS -o {folder}/` or `puppet face-from-photo`)")
    try:
        meta = json.loads((folder / FACE_JSON).read_text("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise FaceFileError(f"{folder / FACE_JSON}: not JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise FaceFileError(f"{folder / FACE_JSON}: not a face folder description")
    mesh = read_obj(folder / FACE_OBJ)
    positions, triangles, triangle_uv = mesh.triangulated()
    feature_vertices = {k: int(e["index"]) for k, e in meta["feature_points"].items() if e.get("index") is not None}
    feature_points = {k: positions[feature_vertices[k]].copy() if k in feature_vertices else np.array(e["xyz"], float)
                      for k, e in meta["feature_points"].items()}
    return TexturedFace(
        name=meta.get("name") or folder.name,
        vertices=positions,
        triangles=triangles,
        parts={k: np.array(v, dtype=np.int32) for k, v in meta["parts"].items()},
        feature_points=feature_points,
        feature_vertices=feature_vertices,
        pivots={k: np.array(v, dtype=np.float64) for k, v in meta["pivots"].items()},
        contours={k: np.array(v, dtype=np.int32) for k, v in meta["contours"].items()},
        colors=mesh.colors,
        placement=np.array(meta["placement"], dtype=np.float64) if "placement" in meta else None,
        **_texture(folder, meta, mesh, positions, triangles, triangle_uv),
        rig_file=folder / FACE_RIG if (folder / FACE_RIG).is_file() else None,
    )


def _texture(folder: Path, meta: dict, mesh, positions: np.ndarray, triangles: np.ndarray,
             triangle_uv: np.ndarray | None) -> dict:
    """The texture fields of a textured folder (texture.png there), else none."""
    if not (folder / FACE_TEXTURE).is_file():
        return {}
    if triangle_uv is None or not np.array_equal(triangle_uv, triangles) or len(mesh.uvs) != len(positions):
        raise FaceFileError(f"{folder / FACE_OBJ}: expected one texture coordinate per vertex (f a/a b/b c/c)")
    with Image.open(folder / FACE_TEXTURE) as image:
        texture = np.asarray(image.convert("RGB"))
    weight = np.array(meta.get("texture_weight", []), dtype=np.float32)
    if len(weight) != len(positions):
        raise FaceFileError(f"{folder / FACE_JSON}: {len(weight)} texture weights for {len(positions)} vertices")
    return {"uv": mesh.uvs.astype(np.float32), "triangle_uv": triangles.copy(), "texture": texture,
            "texture_weight": weight}


def load_folder_rig(path: str | os.PathLike):
    """The rig saved in a face folder (``face.rig``)."""
    return load_rig(Path(path) / FACE_RIG)
