"""A GLB head for tests, built from the embedded default face as an artist's file would be: each
part a mesh of its own on a node of its own, each with its own material, the skin textured, and
ARKit-named morph targets; and the same head as an OBJ with an MTL (``write_obj_head``). Nothing
outside the project is needed, but for real morph targets (``shapes``): the MakeHuman ARKit shapes
(``../shared/assets/makehuman/faceunits_arkit``), applied to the default face through its source
vertices (``puppet.face.examples.load_examples``)."""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np
from PIL import Image

from puppet.bench.assets import shared_assets
from puppet.face.default import default_face
from puppet.face.examples import load_examples

ARKIT_SHAPES = shared_assets() / "makehuman" / "faceunits_arkit"
PART_ORDER = ("skin", "eye_l", "eye_r", "teeth_upper", "teeth_lower", "tongue")
MESH_NAMES = {"skin": "Head", "eye_l": "EyeLeft", "eye_r": "EyeRight", "teeth_upper": "TeethUpper",
              "teeth_lower": "TeethLower", "tongue": "Tongue"}
COLORS = {"skin": (1.0, 1.0, 1.0), "eye_l": (0.9, 0.9, 0.92), "eye_r": (0.9, 0.9, 0.92),
          "teeth_upper": (0.85, 0.8, 0.7), "teeth_lower": (0.85, 0.8, 0.7), "tongue": (0.6, 0.1, 0.1)}
EYE_FACTOR = (0.05, 0.2, 0.8)  # linear blue: the eyes' base colour, far from any skin tone
SKIN_TEXTURE = np.array([[[200, 120, 90], [220, 150, 120]], [[180, 100, 80], [240, 170, 140]]], dtype=np.uint8)


def skin_texture(size: int = 8) -> np.ndarray:
    """The skin's base colour texture: 2 x 2 tiles of four skin tones, ``size`` pixels a side."""
    return np.repeat(np.repeat(SKIN_TEXTURE, size // 2, axis=0), size // 2, axis=1)


def part_order() -> np.ndarray:
    """The default face's vertex indices in the GLB's order (its parts one after another)."""
    face = default_face()
    return np.concatenate([face.parts[p] for p in PART_ORDER])


def skin_uv(face) -> np.ndarray:
    """Per skin vertex a uv (glTF's: v down) from its x, y across the skin's box."""
    p = face.vertices[face.parts["skin"], :2]
    t = (p - p.min(axis=0)) / np.ptp(p, axis=0)
    return np.c_[t[:, 0], 1.0 - t[:, 1]]


class _Blob:
    """The binary chunk and the bufferViews / accessors that describe it."""

    def __init__(self) -> None:
        self.data, self.views, self.accessors = bytearray(), [], []

    def view(self, raw: bytes) -> int:
        self.data += b"\0" * (-len(self.data) % 4)
        self.views.append({"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)})
        self.data += raw
        return len(self.views) - 1

    def add(self, array: np.ndarray, kind: str, component: int = 5126) -> int:
        dtype = {5126: "<f4", 5125: "<u4"}[component]
        view = self.view(np.ascontiguousarray(array, dtype=dtype).tobytes())
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[kind]
        acc = {"bufferView": view, "componentType": component, "count": int(np.size(array) // width), "type": kind}
        if kind == "VEC3" and component == 5126:
            flat = np.asarray(array, dtype=np.float64).reshape(-1, 3)
            acc |= {"min": flat.min(axis=0).tolist(), "max": flat.max(axis=0).tolist()}
        self.accessors.append(acc)
        return len(self.accessors) - 1


def shapes(names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """{ARKit name: (N, 3) displacement of the default face} for the MakeHuman shapes named."""
    every = load_examples(default_face(), ARKIT_SHAPES)
    return {n: every[n] for n in names}


def head_document(morphs: dict[str, np.ndarray] | None = None, *, vrm: int | None = None,
                  unknown_extension: bool = False, names: dict[str, str] | None = None,
                  split_skin: bool = False) -> tuple[dict, bytes]:
    """(glTF JSON, binary chunk) of the default face as six meshes (module docstring); ``morphs``
    ({name: (N, 3) displacement of the default face}) become every mesh's morph targets, ``vrm``
    0 or 1 adds that VRM version's expressions (capitalised names binding the targets),
    ``unknown_extension`` an extension no reader knows, ``names`` other mesh names by part;
    ``split_skin`` writes the skin as two primitives, its left and right halves, each with its own
    copy of the mid-line's vertices (as an exporter splits a mesh along a uv seam)."""
    face = default_face()
    names = {**MESH_NAMES, **(names or {})}
    morphs = morphs or {}
    blob = _Blob()
    image = io.BytesIO()
    Image.fromarray(skin_texture()).save(image, format="PNG")
    doc: dict = {"asset": {"version": "2.0", "generator": "tests/gltfface.py"}, "scene": 0,
                 "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "materials": [],
                 "images": [{"bufferView": blob.view(image.getvalue()), "mimeType": "image/png"}],
                 "textures": [{"source": 0}]}
    for k, part in enumerate(PART_ORDER):
        pbr: dict = {"baseColorFactor": [*(EYE_FACTOR if part.startswith("eye") else COLORS[part]), 1.0]}
        if part == "skin":
            pbr["baseColorTexture"] = {"index": 0}
        primitives = [_primitive(blob, face, ids, tris, k, morphs, part == "skin")
                      for ids, tris in _halves(face, part, split_skin)]
        doc["materials"].append({"name": f"M_{names[part]}", "pbrMetallicRoughness": pbr})
        doc["meshes"].append({"name": names[part], "primitives": primitives,
                              **({"extras": {"targetNames": list(morphs)}} if morphs else {})})
        node = {"name": names[part], "mesh": k}
        if unknown_extension:
            node["extensions"] = {"EXT_made_up_by_nobody": {"anything": [1, 2, 3]}}
        doc["nodes"].append(node)
        doc["scenes"][0]["nodes"].append(k)
    if unknown_extension:
        doc["extensionsUsed"] = ["EXT_made_up_by_nobody"]
        doc["extensions"] = {"EXT_made_up_by_nobody": {"version": 7}}
    if vrm is not None:
        _add_vrm(doc, list(morphs), vrm)
    blob.data += b"\0" * (-len(blob.data) % 4)
    doc |= {"bufferViews": blob.views, "accessors": blob.accessors, "buffers": [{"byteLength": len(blob.data)}]}
    return doc, bytes(blob.data)


def _halves(face, part: str, split: bool) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(default-face vertices, their triangles)] of a part: whole, or the skin's two halves."""
    tris = face.triangles[np.isin(face.triangles[:, 0], face.parts[part])]
    if not (split and part == "skin"):
        return [(face.parts[part], tris)]
    left = face.vertices[tris].mean(axis=1)[:, 0] >= 0
    return [(np.unique(t), t) for t in (tris[left], tris[~left])]


def glb_vertex(split_skin: bool = False) -> np.ndarray:
    """Per default-face vertex, its (first) vertex in the test GLB."""
    face = default_face()
    order = np.concatenate([ids for part in PART_ORDER for ids, _ in _halves(face, part, split_skin)])
    where = np.full(len(face.vertices), -1)
    where[order[::-1]] = np.arange(len(order))[::-1]
    return where


def _primitive(blob: _Blob, face, ids: np.ndarray, tris: np.ndarray, material: int,
               morphs: dict[str, np.ndarray], textured: bool) -> dict:
    local = np.full(len(face.vertices), -1)
    local[ids] = np.arange(len(ids))
    attributes = {"POSITION": blob.add(face.vertices[ids], "VEC3")}
    if textured:
        uv = np.zeros((len(face.vertices), 2))
        uv[face.parts["skin"]] = skin_uv(face)
        attributes["TEXCOORD_0"] = blob.add(uv[ids], "VEC2")
    primitive = {"attributes": attributes, "indices": blob.add(local[tris].astype(np.uint32).ravel(), "SCALAR", 5125),
                 "material": material}
    if morphs:
        primitive["targets"] = [{"POSITION": blob.add(d[ids], "VEC3")} for d in morphs.values()]
    return primitive


def _add_vrm(doc: dict, targets: list[str], version: int) -> None:
    """VRM expressions named as "perfect sync" models name them (capitalised ARKit names), and a
    "Surprised" one binding two targets at half weight each."""
    meshes = range(len(doc["meshes"]))
    named = {t[0].upper() + t[1:]: [(m, i, 1.0) for m in meshes] for i, t in enumerate(targets)}
    named["Surprised"] = [(m, i, 0.5) for m in meshes for i in range(min(2, len(targets)))]
    doc.setdefault("extensionsUsed", []).append("VRM" if version == 0 else "VRMC_vrm")
    if version == 0:  # VRM 0.x binds meshes, weights 0-100, and its model faces -z
        groups = [{"name": n, "binds": [{"mesh": m, "index": i, "weight": 100 * w} for m, i, w in b]}
                  for n, b in named.items()]
        doc.setdefault("extensions", {})["VRM"] = {"blendShapeMaster": {"blendShapeGroups": groups}}
        for node in doc["nodes"]:
            node["rotation"] = [0.0, 1.0, 0.0, 0.0]  # half a turn about y: facing -z as VRM 0.x says
    else:  # VRM 1.0 binds nodes (node k holds mesh k here), weights 0-1
        custom = {n: {"morphTargetBinds": [{"node": m, "index": i, "weight": w} for m, i, w in b]}
                  for n, b in named.items()}
        doc.setdefault("extensions", {})["VRMC_vrm"] = {"specVersion": "1.0", "expressions": {"custom": custom}}


def write_glb(path: Path, doc: dict, blob: bytes) -> Path:
    """Write a GLB container: header, JSON chunk, BIN chunk."""
    text = json.dumps(doc).encode("utf-8")
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    path.write_bytes(struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(text), 0x4E4F534A) + text
                     + struct.pack("<II", len(blob), 0x004E4942) + blob)
    return path


def write_head(path: Path, morphs: dict[str, np.ndarray] | None = None, **options) -> Path:
    """The test head (``head_document``) written as a GLB at ``path``."""
    return write_glb(path, *head_document(morphs, **options))


def write_obj_head(folder: Path) -> Path:
    """The default face as ``head.obj`` in ``folder``, vertex for vertex: one ``usemtl`` group per
    part (the GLB's mesh names), ``head.mtl`` giving each its Kd (the GLB's factors as written, the
    eyes' too) and the skin ``map_Kd skin.png`` (``skin_texture``), a ``vt`` per vertex."""
    face = default_face()
    Image.fromarray(skin_texture()).save(folder / "skin.png")
    mtl = [f"newmtl M_{MESH_NAMES[p]}\nKd {' '.join(map(str, EYE_FACTOR if p.startswith('eye') else COLORS[p]))}"
           + ("\nmap_Kd skin.png" if p == "skin" else "") for p in PART_ORDER]
    (folder / "head.mtl").write_text("\n".join(mtl) + "\n")
    uv = np.zeros((len(face.vertices), 2))
    uv[face.parts["skin"]] = skin_uv(face) * [1, -1] + [0, 1]  # OBJ's v runs up the image
    lines = ["mtllib head.mtl"] + [f"v {x!r} {y!r} {z!r}" for x, y, z in face.vertices.tolist()]
    lines += [f"vt {u!r} {v!r}" for u, v in uv.tolist()]
    for part in PART_ORDER:
        lines.append(f"usemtl M_{MESH_NAMES[part]}")
        tris = face.triangles[np.isin(face.triangles[:, 0], face.parts[part])] + 1
        lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in tris.tolist()]
    path = folder / "head.obj"
    path.write_text("\n".join(lines) + "\n")
    return path
