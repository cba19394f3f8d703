"""Your own head as the artist made it: a GLB / glTF / VRM (or an OBJ with its MTL) loads with its
meshes apart as the face's parts, its material colours and base-colour textures, its morph
targets as example shapes, and keeps all of it through landmarks, the rig and a face folder; bad
files are one clear line each. The GLB is the embedded face written as an artist's file would be
(``tests/gltfface.py``)."""

from __future__ import annotations

import base64
import json
import re

import numpy as np
import pytest
from gltfface import (
    ARKIT_SHAPES,
    COLORS,
    EYE_FACTOR,
    PART_ORDER,
    glb_vertex,
    head_document,
    part_order,
    shapes,
    skin_texture,
    skin_uv,
    write_glb,
    write_head,
    write_obj_head,
)

from puppet.bench.assets import shared_assets
from puppet.cli import main
from puppet.face.autorig import build_rig
from puppet.face.default import default_face
from puppet.face.examples import load_examples
from puppet.face.gltfread import MAX_VERTICES, read_gltf, srgb_encode
from puppet.face.landmarks import FDP_NEEDED
from puppet.face.load import load_face
from puppet.face.meshfile import write_bare_obj
from puppet.face.model import FaceFileError
from puppet.photo.detect import photo_python
from puppet.runtime.fapcalibration import fit_faps, relative_residual
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import Renderer

ICT = shared_assets() / "ict_facekit" / "generic_neutral_mesh.obj"
FAKE_MORPHS = ("jawOpen", "mouthSmileLeft", "eyeBlinkLeft")


def fake_morphs() -> dict[str, np.ndarray]:
    """Three ARKit-named displacements of the default face, distinct and reproducible."""
    rng = np.random.default_rng(3)
    n = len(default_face().vertices)
    return {name: rng.normal(scale=0.01, size=(n, 3)) for name in FAKE_MORPHS}


def glb_landmarks(split_skin: bool = False) -> dict[str, int]:
    """The FDPs a rig needs, as vertices of the test GLB (its own vertex order)."""
    where = glb_vertex(split_skin)
    return {f: int(where[default_face().feature_vertices[f]]) for f in FDP_NEEDED}


@pytest.fixture(scope="module")
def head(tmp_path_factory):
    return write_head(tmp_path_factory.mktemp("glb") / "head.glb", fake_morphs())


def test_a_glb_head_keeps_its_meshes_as_parts_with_their_colours_and_texture(head):
    face, default = load_face(head), default_face()
    order = part_order()
    np.testing.assert_allclose(face.vertices, default.vertices[order], atol=1e-6)  # float32 in the file
    assert sorted(face.parts) == sorted(default.parts)
    start = 0
    for part in PART_ORDER:
        size = len(default.parts[part])
        assert np.array_equal(face.parts[part], np.arange(start, start + size)), part
        start += size
    eye = face.parts["eye_l"]
    np.testing.assert_allclose(face.colors[eye], np.tile(srgb_encode(EYE_FACTOR), (len(eye), 1)), atol=1e-6)
    np.testing.assert_allclose(face.colors[face.parts["tongue"]][0], srgb_encode(COLORS["tongue"]), atol=1e-6)
    skin = face.parts["skin"]
    assert face.texture_weight[skin].min() == 1 and face.texture_weight[np.setdiff1d(order, skin)].max() == 0
    h, w = face.texture.shape[:2]  # each skin vertex's atlas texel is the texel its own uv named
    u, v = face.uv[skin, 0], face.uv[skin, 1]
    atlas = face.texture[np.clip(((1 - v) * h).astype(int), 0, h - 1), np.clip((u * w).astype(int), 0, w - 1)]
    uv = skin_uv(default)
    own = skin_texture()[np.clip((uv[:, 1] * 8).astype(int), 0, 7), np.clip((uv[:, 0] * 8).astype(int), 0, 7)]
    inside = (np.abs(uv * 8 - np.round(uv * 8)) > 0.05).all(axis=1)  # clear of a texel's edge
    assert inside.sum() > 1000 and np.array_equal(atlas[inside], own[inside])


def test_unnamed_eyeballs_are_found_by_shape_and_one_teeth_mesh_is_split_into_rows(tmp_path):
    names = {"skin": "Body", "eye_l": "Sphere", "eye_r": "Sphere.001", "teeth_upper": "Teeth",
             "teeth_lower": "Teeth", "tongue": "Tongue"}
    face, default = load_face(write_head(tmp_path / "blender.glb", names=names)), default_face()
    start = {}
    for part in PART_ORDER:
        start[part] = sum(len(default.parts[p]) for p in PART_ORDER[:PART_ORDER.index(part)])
    for part in ("eye_l", "eye_r", "teeth_upper", "teeth_lower"):
        n = len(default.parts[part])
        assert np.array_equal(face.parts[part], np.arange(start[part], start[part] + n)), part


def test_an_obj_s_mtl_colours_and_textures_it_as_the_glb(tmp_path, head):
    obj, glb = load_face(write_obj_head(tmp_path)), load_face(head)
    default = default_face()
    assert {k: v.tolist() for k, v in obj.parts.items()} == {k: v.tolist() for k, v in default.parts.items()}
    order = part_order()
    eye = default.parts["eye_l"]
    np.testing.assert_allclose(obj.colors[eye], np.tile(EYE_FACTOR, (len(eye), 1)), atol=1e-6)  # Kd as written
    skin = default.parts["skin"]
    assert obj.texture_weight[skin].min() == 1 and obj.texture_weight[eye].max() == 0
    assert np.array_equal(obj.texture, glb.texture)
    where = np.empty(len(order), dtype=np.int64)
    where[order] = np.arange(len(order))
    np.testing.assert_allclose(obj.uv[skin], glb.uv[where[skin]], atol=1e-6)


@pytest.mark.parametrize("vrm", [0, 1])
def test_a_vrm_gives_its_expressions_and_ignores_an_extension_it_does_not_know(tmp_path, vrm):
    morphs = fake_morphs()
    path = write_head(tmp_path / "avatar.vrm", morphs, vrm=vrm, unknown_extension=True)
    scene = read_gltf(path)
    assert {"JawOpen", "MouthSmileLeft", "EyeBlinkLeft", "Surprised"} <= set(scene.expressions)
    assert "EXT_made_up_by_nobody" in scene.extensions
    face = load_face(path)
    np.testing.assert_allclose(face.vertices, default_face().vertices[part_order()], atol=1e-6)  # 0.x turned
    examples = load_examples(face, path)
    assert sorted(examples) == sorted([*FAKE_MORPHS, "Surprised"])  # ARKit spelling, each once
    order = part_order()
    np.testing.assert_allclose(examples["jawOpen"], morphs["jawOpen"][order], atol=1e-6)
    np.testing.assert_allclose(examples["Surprised"], 0.5 * (morphs["jawOpen"] + morphs["mouthSmileLeft"])[order],
                               atol=1e-6)


def test_a_landmarked_glb_rigs_with_turning_eyes_and_rigid_teeth(head):
    face = load_face(head, landmarks=glb_landmarks())
    assert {k: len(v) for k, v in face.parts.items()} == {k: len(v) for k, v in default_face().parts.items()}
    runtime = Runtime(face, build_rig(face), dtype=np.float64, cache=False)
    rest = runtime.deform_faps()
    looked = runtime.deform_faps({"yaw_l_eyeball": 30000})
    eye = face.parts["eye_l"]
    assert np.linalg.norm(looked[eye] - rest[eye], axis=1).max() > 0.01 * np.ptp(rest[eye], axis=0).max()
    assert _rigid(rest[eye], looked[eye])
    opened = runtime.deform_faps({"open_jaw": 600})
    lower, upper = face.parts["teeth_lower"], face.parts["teeth_upper"]
    assert np.abs(opened[lower] - rest[lower]).max() > 0 and _rigid(rest[lower], opened[lower])
    np.testing.assert_allclose(opened[upper], rest[upper], atol=1e-9)


def test_a_skin_split_along_a_uv_seam_is_one_skin_to_the_landmarks(tmp_path):
    """An exporter splits vertices along uv seams: a skin whose halves meet only at the mid-line
    (each half its own copy of it) is still one skin, whose lip and lid loops cross the mid-line,
    and ``build_rig`` joins it too: every region covers the places it covers on the whole skin
    (unjoined, the mouth bag took the far half for the mouth's inside and emptied the cheeks)."""
    face = load_face(write_head(tmp_path / "seam.glb", split_skin=True), landmarks=glb_landmarks(split_skin=True))
    default = default_face()
    copies = len(face.vertices) - len(default.vertices)
    assert copies > 20 and len(face.parts["skin"]) == len(default.parts["skin"]) + copies
    for loop in ("mouth_opening", "vermilion_border"):
        x = face.vertices[face.contours[loop], 0]
        assert x.min() < 0 < x.max(), loop
    assert {k: len(v) for k, v in face.contours.items() if "lid" in k} == \
        {k: len(v) for k, v in load_face(write_head(tmp_path / "whole.glb"), landmarks=glb_landmarks()).contours.items()
         if "lid" in k}
    whole = load_face(write_head(tmp_path / "whole.glb"), landmarks=glb_landmarks())
    for split, joined in zip(build_rig(face).regions, build_rig(whole).regions, strict=True):
        places = [{tuple(p) for p in np.round(f.vertices[r.vertices], 6)} for f, r in ((face, split), (whole, joined))]
        assert split.name == joined.name and places[0] == places[1], split.name


def _rigid(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether b is a turned and moved copy of a (every distance to the first few points kept)."""
    pick = np.linspace(0, len(a) - 1, 12).astype(int)
    da = np.linalg.norm(a[:, None] - a[pick][None], axis=2)
    db = np.linalg.norm(b[:, None] - b[pick][None], axis=2)
    return bool(np.abs(da - db).max() < 1e-6 * np.ptp(a, axis=0).max())


def test_a_rigged_glb_folder_keeps_parts_colours_and_texture(tmp_path, head):
    landmarks = tmp_path / "points.json"
    landmarks.write_text(json.dumps(glb_landmarks()))
    assert main(["rig", str(head), "--landmarks", str(landmarks), "-o", str(tmp_path / "me")]) == 0
    face, folder = load_face(head), load_face(tmp_path / "me")
    assert {k: v.tolist() for k, v in folder.parts.items()} == {k: v.tolist() for k, v in face.parts.items()}
    np.testing.assert_allclose(folder.colors, face.colors, atol=1e-4)
    assert np.array_equal(folder.texture, face.texture)
    np.testing.assert_allclose(folder.uv, face.uv, atol=1e-6)
    np.testing.assert_allclose(folder.texture_weight, face.texture_weight)
    assert folder.placement is not None


def test_the_eyes_of_a_glb_render_in_their_own_colour(egl, head):
    face = load_face(head)
    with Renderer.for_face(face, width=320, height=320) as r:
        r.aim(face.vertices)
        image = r.render(face.vertices.astype(np.float32)).astype(int)
        eye_front = face.vertices[face.parts["eye_l"]][np.argmax(face.vertices[face.parts["eye_l"], 2])]
        cheek = face.vertices[face.parts["skin"]][np.argmin(np.linalg.norm(
            face.vertices[face.parts["skin"]] - (eye_front - (0, 0.25, 0)), axis=1))]
        (ex, ey), (cx, cy) = r.project(np.array([eye_front, cheek])).astype(int)
    eye_px, skin_px = image[ey, ex, :3], image[cy, cx, :3]
    assert eye_px[2] > eye_px[0] + 40, eye_px  # blue, as its material says
    assert skin_px[0] > skin_px[2] + 40, skin_px  # skin toned, as its texture says


@pytest.mark.skipif(not ICT.is_file(), reason=f"{ICT} is not here (../shared/assets/ict_facekit)")
def test_the_ict_head_s_materials_colour_its_eyes_apart_from_its_skin(egl):
    face = load_face(ICT)
    assert {"eye_l", "eye_r", "teeth_upper", "teeth_lower"} <= set(face.parts)
    for side in ("eye_l", "eye_r"):
        assert abs(face.vertices[face.parts[side], 0].mean()) > 1  # apart, either side of the mid-line
    assert face.vertices[face.parts["eye_l"], 0].mean() > 0
    eye = face.parts["eye_l"]
    assert face.colors[eye].min() < 0.25  # the iris's Kd 0.2, skin's is 0.6
    with Renderer.for_face(face, width=400, height=400) as r:
        r.aim(face.vertices[eye], margin=3.0)
        image = r.render(face.vertices.astype(np.float32)).astype(int)
        front = face.vertices[eye][np.argmax(face.vertices[eye, 2])]
        x, y = r.project(front[None])[0].astype(int)
        cheek = r.project((front - (0, 3.0, 0))[None])[0].astype(int)
    assert image[y, x, :3].sum() + 120 < image[cheek[1], cheek[0], :3].sum()  # a dark iris, not skin


@pytest.mark.slow
def test_calibrate_face_learns_from_a_glb_s_morph_targets(tmp_path, capsys):
    """A GLB of the embedded face with four of its artist's ARKit shapes as morph targets, rigged
    from its landmarks and calibrated from the GLB itself: the held-out smile fits better than on
    the rig before calibration."""
    if not ARKIT_SHAPES.is_dir():
        pytest.skip(f"{ARKIT_SHAPES} is not here (../shared/assets/makehuman)")
    head = write_head(tmp_path / "head.glb", shapes(("mouthSmileLeft", "jawOpen", "browInnerUp", "mouthSmileRight")))
    landmarks = tmp_path / "points.json"
    landmarks.write_text(json.dumps(glb_landmarks()))
    out = tmp_path / "me"
    assert main(["rig", str(head), "--landmarks", str(landmarks), "-o", str(out)]) == 0
    before = Runtime(load_face(out), dtype=np.float64)
    smile = load_examples(load_face(out), head)["mouthSmileRight"]
    uncalibrated = relative_residual(before, fit_faps(before, smile), smile)
    assert main(["calibrate-face", "--face", str(out), "--examples", str(head), "-o", str(out),
                 "--hold-out", "mouthSmileRight"]) == 0
    text = capsys.readouterr().out
    held = float(re.search(r"held out: +median ([0-9.]+)", text).group(1))
    assert held < uncalibrated - 0.02, (held, uncalibrated, text)
    face = load_face(out)
    assert face.texture is not None and "eye_l" in face.parts


@pytest.mark.parametrize("case, words", [
    ("no mesh", ["no triangle mesh"]),
    ("truncated", ["truncated GLB"]),
    ("garbage", ["not a binary glTF"]),
    ("missing buffer", ["buffers[0]", "nowhere.bin", "cannot be read"]),
    ("2M vertices", [f"{2_000_000 + 10222 - 4326:,} vertices", f"{MAX_VERTICES:,}"]),  # the skin's 4326 made 2M
    ("EXT_meshopt_compression", ["EXT_meshopt_compression", "meshopt", "without compression"]),
    ("KHR_draco_mesh_compression", ["KHR_draco_mesh_compression", "Draco", "without compression"]),
    ("KHR_texture_basisu", ["KHR_texture_basisu", "KTX2", "PNG or JPEG"]),
])
def test_a_bad_glb_is_one_clear_line(tmp_path, case, words):
    path = tmp_path / ("head.gltf" if case == "missing buffer" else "head.glb")
    doc, blob = head_document()
    if case == "no mesh":
        write_glb(path, {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"name": "empty"}]}, b"")
    elif case == "truncated":
        path.write_bytes(write_glb(path, doc, blob).read_bytes()[:5000])
    elif case == "garbage":
        path.write_bytes(bytes(range(256)) * 10)
    elif case == "missing buffer":
        path.write_text(json.dumps(doc | {"buffers": [{"uri": "nowhere.bin", "byteLength": len(blob)}]}))
    elif case == "2M vertices":
        doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["count"] = 2_000_000
        write_glb(path, doc, blob)
    else:  # a file that cannot be read without a compression extension
        write_glb(path, doc | {"extensionsUsed": [case], "extensionsRequired": [case]}, blob)
    with pytest.raises(FaceFileError) as err:
        load_face(path)
    text = str(err.value)
    assert "\n" not in text and str(path) in text and all(w in text for w in words), text


def test_fifty_meshes_load_and_a_gltf_with_embedded_buffers_reads_alike(tmp_path, head):
    doc, blob = head_document()
    skin = doc["meshes"][0]
    for k in range(44):  # 44 more copies of the skin, moved aside: 50 meshes
        doc["meshes"].append({"name": f"Hair_{k}", "primitives": skin["primitives"]})
        doc["nodes"].append({"name": f"Hair_{k}", "mesh": len(doc["meshes"]) - 1, "translation": [0, 10 + k, 0]})
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)
    face = load_face(write_glb(tmp_path / "fifty.glb", doc, blob))
    assert len(face.vertices) == len(default_face().vertices) + 44 * len(default_face().parts["skin"])
    assert {"eye_l", "eye_r", "teeth_upper", "teeth_lower", "tongue"} <= set(face.parts)
    doc, blob = head_document()
    embedded = doc | {"buffers": [{"uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode(),
                                   "byteLength": len(blob)}]}
    (tmp_path / "head.gltf").write_text(json.dumps(embedded))
    assert np.array_equal(load_face(tmp_path / "head.gltf").vertices, load_face(head).vertices)


def test_accessors_read_sparse_normalized_and_strided_values(tmp_path):
    """A POSITION given sparsely over zeros, a normalized ubyte COLOR_0 and an interleaved uv."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype="<f4")
    colour = np.array([[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255]], dtype="<u1")
    interleaved = np.zeros(3, dtype=[("uv", "<f4", 2), ("pad", "<f4", 1)])
    interleaved["uv"] = [[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]]
    index = np.array([1, 2], dtype="<u2")
    parts = [index.tobytes() + b"\0\0", positions[1:].tobytes(), colour.tobytes(), interleaved.tobytes()]
    offsets = np.cumsum([0] + [len(p) for p in parts])
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "buffers": [{"byteLength": int(offsets[-1])}],
           "bufferViews": [{"buffer": 0, "byteOffset": int(o), "byteLength": len(p)} for o, p in zip(offsets, parts)],
           "accessors": [
               {"componentType": 5126, "count": 3, "type": "VEC3",
                "sparse": {"count": 2, "indices": {"bufferView": 0, "componentType": 5123},
                           "values": {"bufferView": 1}}},
               {"bufferView": 2, "componentType": 5121, "count": 3, "type": "VEC4", "normalized": True},
               {"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC2"}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1, "TEXCOORD_0": 2}}]}]}
    doc["bufferViews"][3]["byteStride"] = 12
    piece = read_gltf(write_glb(tmp_path / "tiny.glb", doc, b"".join(parts))).pieces[0]
    np.testing.assert_allclose(piece.positions, positions)
    np.testing.assert_allclose(piece.colors, np.eye(3), atol=1e-6)
    np.testing.assert_allclose(piece.uv, interleaved["uv"], atol=1e-7)
    assert piece.triangles.tolist() == [[0, 1, 2]]


@pytest.mark.skipif(photo_python() is None, reason="no photo environment (.venv-photo: tools/setup.sh makes it)")
def test_a_glb_head_alone_rigs_from_found_landmarks_with_its_eyes_teeth_and_texture(tmp_path, egl):
    """``puppet rig head.glb -o me/`` with nothing else (its found landmarks once put one vertex on
    both lids of a loop that touched itself: 'duplicate sites'): the folder has simple lip and lid
    loops, renders with its texture and blue eyes, its eyes turn and its lower teeth open rigidly."""
    head = write_head(tmp_path / "head.glb")
    assert main(["rig", str(head), "-o", str(tmp_path / "me")]) == 0
    face = load_face(tmp_path / "me")
    for name, loop in face.contours.items():
        assert len(set(loop.tolist())) == len(loop), name
    assert np.array_equal(face.texture, load_face(head).texture)
    runtime = Runtime(face, dtype=np.float64)
    rest = runtime.deform_faps()
    eye = face.parts["eye_l"]
    looked = runtime.deform_faps({"yaw_l_eyeball": 30000})
    assert np.linalg.norm(looked[eye] - rest[eye], axis=1).max() > 0.01 * np.ptp(rest[eye], axis=0).max()
    assert _rigid(rest[eye], looked[eye])
    opened = runtime.deform_faps({"open_jaw": 600})
    lower = face.parts["teeth_lower"]
    assert np.abs(opened[lower] - rest[lower]).max() > 0 and _rigid(rest[lower], opened[lower])
    with Renderer.for_face(face, width=320, height=320) as r:
        r.aim(rest)
        image = r.render(rest.astype(np.float32)).astype(int)
        front = rest[eye][np.argmax(rest[eye, 2])]
        skin = rest[face.parts["skin"]]
        cheek = skin[np.argmin(np.linalg.norm(skin - (front - (0, 0.25 * np.ptp(rest[eye, 1]) * 4, 0)), axis=1))]
        (ex, ey), (cx, cy) = r.project(np.array([front, cheek])).astype(int)
    assert image[ey, ex, 2] > image[ey, ex, 0] + 40, image[ey, ex]  # blue, as its material says
    assert image[cy, cx, 0] > image[cy, cx, 2] + 40, image[cy, cx]  # skin toned, as its texture says


def test_two_feature_points_on_one_place_are_named_with_what_to_do(tmp_path, capsys):
    """Issue 38: not 'duplicate sites ... indices 21 and 40' but the feature points and the fix."""
    marks = glb_landmarks() | {f: int(glb_vertex()[default_face().feature_vertices["4.1"]]) for f in ("4.1", "4.3")}
    (tmp_path / "points.json").write_text(json.dumps(marks))
    head = write_head(tmp_path / "head.glb")
    assert main(["rig", str(head), "--landmarks", str(tmp_path / "points.json"), "-o", str(tmp_path / "me")]) != 0
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "feature points 4.1 and 4.3 fall on the same place" in line and "pick-landmarks" in line, line


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_a_mesh_of_millions_of_vertices_is_refused_in_one_line_as_a_glb_is(tmp_path, suffix):
    """The OBJ's vertex lines are counted before any is parsed; trimesh's formats after loading."""
    n = MAX_VERTICES + 1
    path = tmp_path / f"big{suffix}"
    if suffix == ".obj":
        path.write_text("v 0 0 0\n" * n + "f 1 2 3\n")
    else:
        header = f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n" \
                 "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        face = bytes([3]) + np.arange(3, dtype="<i4").tobytes()
        path.write_bytes(header.encode() + np.zeros((n, 3), "<f4").tobytes() + face)
    with pytest.raises(FaceFileError) as err:
        load_face(path)
    text = str(err.value)
    assert "\n" not in text and str(path) in text and f"{n:,} vertices" in text and f"{MAX_VERTICES:,}" in text, text


def _awkward(case: str, path):
    """The test head turned to look along +x in its file, standing on a body box four heads tall
    (a whole figure), or as an OBJ whose skin repeats every 50th triangle and grows a fin (an edge
    of three triangles)."""
    doc, blob = head_document()
    if case == "sideways":
        for node in doc["nodes"]:
            node["rotation"] = [0.0, float(np.sin(np.pi / 4)), 0.0, float(np.cos(np.pi / 4))]
        return write_glb(path.with_suffix(".glb"), doc, blob)
    v, t = default_face().vertices, default_face().triangles
    if case == "non-manifold":
        fin = v[t[0, 0]] + (0.0, 0.0, 0.03 * np.ptp(v[:, 1]))
        triangles = np.vstack([t, t[::50], [[*t[0, :2], len(v)]]])
        return write_bare_obj(path.with_suffix(".obj"), np.vstack([v, fin]), triangles)
    lo, hi = v.min(axis=0), v.max(axis=0)
    h, c = hi[1] - lo[1], (lo + hi) / 2
    box = np.array([[x, y, z] for x in (c[0] - h, c[0] + h) for y in (lo[1] - 4 * h, lo[1] + 0.05 * h)
                    for z in (c[2] - h / 2, c[2] + h / 2)], np.float32)
    sides = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.uint32)
    data = bytearray(blob)
    for array in (box, sides):
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(data), "byteLength": array.nbytes})
        data += array.tobytes()
    n = len(doc["accessors"])
    doc["accessors"] += [{"bufferView": len(doc["bufferViews"]) - 2, "componentType": 5126, "count": 8, "type": "VEC3",
                          "min": box.min(axis=0).tolist(), "max": box.max(axis=0).tolist()},
                         {"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5125, "count": sides.size,
                          "type": "SCALAR"}]
    doc["meshes"].append({"name": "Body", "primitives": [{"attributes": {"POSITION": n}, "indices": n + 1}]})
    doc["nodes"].append({"name": "Body", "mesh": len(doc["meshes"]) - 1})
    doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)
    doc["buffers"] = [{"byteLength": len(data)}]
    return write_glb(path.with_suffix(".glb"), doc, bytes(data))


@pytest.mark.slow
@pytest.mark.skipif(photo_python() is None, reason="no photo environment (.venv-photo: tools/setup.sh makes it)")
@pytest.mark.parametrize("case", ["sideways", "non-manifold"])
def test_an_awkward_head_rigs_from_found_landmarks(tmp_path, case):
    """A face looking sideways in its file, a non-manifold skin: each rigs with no --landmarks, and
    its jaw opens its lower lip away from its upper lip."""
    mesh = _awkward(case, tmp_path / "head")
    assert main(["rig", str(mesh), "-o", str(tmp_path / "me")]) == 0
    face = load_face(tmp_path / "me")
    runtime = Runtime(face, dtype=np.float64)
    rest, opened = runtime.deform_faps(), runtime.deform_faps({"open_jaw": 600})
    lip = face.feature_vertices["2.3"]
    assert rest[lip, 1] - opened[lip, 1] > 0.02 * np.ptp(rest[face.parts["skin"], 1]) > 0
    np.testing.assert_allclose(opened[face.feature_vertices["9.3"]], rest[face.feature_vertices["9.3"]], atol=1e-6)


def test_a_whole_figure_rigs_its_head_and_its_body_stays_with_the_head(tmp_path):
    """A head on a body box (given landmarks): the body is no lash riding the cheeks (two of its
    corners did, and the jaw's fold limit shrank to a twentieth): it stays, and the jaw opens as on
    the head alone."""
    figure = load_face(_awkward("whole figure", tmp_path / "figure"), landmarks=glb_landmarks())
    head = load_face(write_head(tmp_path / "head.glb"), landmarks=glb_landmarks())
    drops = []
    for face in (figure, head):
        runtime = Runtime(face, build_rig(face), dtype=np.float64, cache=False)
        rest, opened = runtime.deform_faps(), runtime.deform_faps({"open_jaw": 600})
        drops.append(rest[face.feature_vertices["2.3"], 1] - opened[face.feature_vertices["2.3"], 1])
        if face is figure:
            body = face.parts["attached"]
            assert len(body) == 8 and np.array_equal(opened[body], rest[body])
    assert drops[0] == pytest.approx(drops[1], rel=1e-6) and drops[1] > 0
