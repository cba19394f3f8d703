"""The face model: the embedded default face, its parts, feature points and FAPU, and load_face."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import puppet
from puppet.face.load import load_face
from puppet.face.meshfile import load_mesh, read_obj, write_bare_obj
from puppet.face.model import Face, FaceFileError, MissingFeaturePointsError

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
BASE_OBJ = SHARED / "assets" / "makehuman" / "base.obj"
needs_shared = pytest.mark.skipif(not BASE_OBJ.is_file(), reason="../shared/assets/makehuman is absent")

PARTS = ("skin", "eye_l", "eye_r", "teeth_upper", "teeth_lower", "tongue")
GENERATED = ("eye_l", "eye_r", "teeth_upper", "teeth_lower", "tongue")  # tongue: reshaped helper
FDP_COUNTS = {2: 14, 3: 14, 4: 6, 5: 4, 6: 4, 7: 1, 8: 10, 9: 15, 10: 10, 11: 6}  # 84 in all
MIRROR = [("2.4", "2.5"), ("2.6", "2.7"), ("2.8", "2.9"), ("2.11", "2.12"), ("2.13", "2.14"),
          ("3.1", "3.2"), ("3.3", "3.4"), ("3.5", "3.6"), ("3.7", "3.12"), ("3.11", "3.8"),
          ("3.9", "3.10"), ("3.13", "3.14"), ("4.1", "4.2"), ("4.3", "4.4"), ("4.5", "4.6"),
          ("5.1", "5.2"), ("5.3", "5.4"), ("6.3", "6.4"), ("8.3", "8.4"), ("8.5", "8.6"),
          ("8.7", "8.8"), ("8.10", "8.9"), ("9.1", "9.2"), ("9.5", "9.4"), ("9.7", "9.6"),
          ("9.13", "9.14"), ("10.1", "10.2"), ("10.3", "10.4"), ("10.5", "10.6"),
          ("10.7", "10.8"), ("10.9", "10.10"), ("11.3", "11.2")]  # (left, right): left has x > 0
MIDLINE = ["2.1", "2.2", "2.3", "2.10", "6.1", "6.2", "7.1", "8.1", "8.2", "9.3", "9.8", "9.9",
           "9.10", "9.11", "9.12", "9.15", "11.1", "11.4", "11.5", "11.6"]


def part_triangles(face: Face, part: str) -> np.ndarray:
    inside = np.zeros(len(face.vertices), dtype=bool)
    inside[face.parts[part]] = True
    return face.triangles[inside[face.triangles].all(axis=1)]


def first_hits(origins, direction, vertices, triangles):
    """(distance, triangle) of each ray's first hit, inf / -1 where it hits nothing."""
    a = vertices[triangles[:, 0]]
    e1, e2 = vertices[triangles[:, 1]] - a, vertices[triangles[:, 2]] - a
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    dist = np.full(len(origins), np.inf)
    tri = np.full(len(origins), -1)
    for i, o in enumerate(origins):
        s = o - a
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ direction) * inv
        t = np.einsum("ij,ij->i", q, e2) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9)
        if hit.any():
            k = int(np.argmin(np.where(hit, t, np.inf)))
            dist[i], tri[i] = t[k], k
    return dist, tri


def lips_closed() -> dict[str, np.ndarray]:
    """The skin vertices the face builder moved to close the lips at rest, per lip's wall."""
    doc = json.loads((REPO / "puppet" / "data" / "default_face.json").read_text())["lips_closed"]
    return {wall: np.asarray(doc[wall]) for wall in ("upper", "lower")}


def lip_line(face: Face, x: np.ndarray) -> np.ndarray:
    """Height midway between the upper and lower arcs of the lips' meeting line, at each x."""
    loop = face.contours["mouth_opening"].tolist()
    i, j = sorted((loop.index(face.feature_vertices["2.4"]), loop.index(face.feature_vertices["2.5"])))
    arcs = [loop[i:j + 1], loop[j:] + loop[:i + 1]]
    ys = []
    for arc in arcs:
        p = face.vertices[arc]
        order = np.argsort(p[:, 0])
        ys.append(np.interp(x, p[order, 0], p[order, 1]))
    return (ys[0] + ys[1]) / 2


# -- the default face ---------------------------------------------------------------------------

def test_default_face_loads_quickly_with_consistent_arrays(face):
    start = time.perf_counter()
    again = load_face()
    assert time.perf_counter() - start < 0.1
    assert again is not face and again.vertices is not face.vertices  # callers get their own copy
    n = len(face.vertices)
    assert face.name == "default"
    assert face.vertices.shape == (n, 3) and face.vertices.dtype == np.float64
    assert face.triangles.shape[1] == 3 and face.triangles.dtype == np.int32
    assert face.triangles.min() >= 0 and face.triangles.max() < n
    assert face.colors.shape == (n, 3) and face.colors.dtype == np.float32
    assert 0.0 <= face.colors.min() and face.colors.max() <= 1.0
    assert face.uv.dtype == np.float32 and face.uv.shape[1] == 2
    assert face.triangle_uv.shape == face.triangles.shape and face.triangle_uv.dtype == np.int32
    assert 0 <= face.triangle_uv.min() and face.triangle_uv.max() < len(face.uv)
    assert face.source_index.shape == (n,) and face.source_index.dtype == np.int32
    assert puppet.load_face is load_face and puppet.Face is Face


def test_parts_are_disjoint_sorted_and_cover_every_vertex(face):
    assert set(PARTS) <= set(face.parts)
    seen = np.zeros(len(face.vertices), dtype=int)
    for name, idx in face.parts.items():
        assert idx.dtype == np.int32 and np.all(np.diff(idx) > 0), name
        seen[idx] += 1
    assert np.all(seen == 1)
    owner = np.empty(len(face.vertices), dtype=object)
    for name, idx in face.parts.items():
        owner[idx] = name
    corners = owner[face.triangles]
    assert np.all(corners[:, 0] == corners[:, 1]) and np.all(corners[:, 1] == corners[:, 2])


def test_generated_vertices_are_marked(face):
    si = face.source_index
    assert np.all(si[face.parts["skin"]] >= 0)
    assert np.all(np.diff(si[face.parts["skin"]]) > 0)  # kept vertices in ascending base order
    for part in GENERATED:
        assert np.all(si[face.parts[part]] == -1), part


@needs_shared
def test_source_index_points_at_the_same_base_vertex(face):
    base = read_obj(BASE_OBJ).positions
    si = face.source_index
    kept = si >= 0
    assert kept.sum() == len(face.parts["skin"])
    sealed = np.zeros(len(si), dtype=bool)
    for wall in lips_closed().values():
        sealed[wall] = True
    np.testing.assert_array_equal(face.vertices[kept & ~sealed], base[si[kept & ~sealed]])
    # the lips closed at rest: the slit's inner walls moved in y only, by at most its width
    moved = face.vertices[sealed] - base[si[sealed]]
    assert np.all(moved[:, [0, 2]] == 0) and 0 < np.abs(moved[:, 1]).max() < 0.015


def test_all_84_feature_points_and_their_vertices(face):
    counts = {}
    for fid in face.feature_points:
        group = int(fid.split(".")[0])
        counts[group] = counts.get(group, 0) + 1
    assert counts == FDP_COUNTS
    for group in (2, 3, 4, 5, 8, 9, 10, 11):
        assert counts[group] > 0
    assert set(face.feature_vertices) == set(face.feature_points) - {"7.1", "11.5"}
    for fid, v in face.feature_vertices.items():
        np.testing.assert_array_equal(face.feature_points[fid], face.vertices[v], err_msg=fid)
    skin = set(face.parts["skin"].tolist())
    for fid in ("2.1", "3.1", "4.3", "5.1", "8.3", "9.3", "10.1", "11.1"):
        assert face.feature_vertices[fid] in skin, fid
    assert face.feature_vertices["6.1"] in set(face.parts["tongue"].tolist())
    assert face.feature_vertices["9.10"] in set(face.parts["teeth_upper"].tolist())
    assert face.feature_vertices["9.11"] in set(face.parts["teeth_lower"].tolist())


def test_left_right_pairs_mirror_and_midline_points_are_on_it(face):
    fp = face.feature_points
    for left, right in MIRROR:
        assert fp[left][0] > 0, left
        np.testing.assert_allclose(fp[right], fp[left] * [-1, 1, 1], atol=1e-9, err_msg=f"{left}/{right}")
    for fid in MIDLINE:
        assert abs(fp[fid][0]) < 1e-9, fid
    np.testing.assert_allclose(face.pivots["eye_r"], face.pivots["eye_l"] * [-1, 1, 1])


def test_feature_points_are_plausible(face):
    fp = face.feature_points
    y = {k: p[1] for k, p in fp.items()}
    assert y["11.4"] > y["11.1"] > y["4.3"] > y["3.13"] > y["3.1"] > y["3.5"] > y["3.3"] > y["3.9"]
    assert y["3.9"] > y["9.3"] > y["9.15"] > y["8.1"] > y["2.2"] >= y["2.3"] > y["8.2"] > y["2.10"] > y["2.1"]
    assert y["9.8"] > y["9.11"] > y["9.10"] > y["9.9"]  # an overbite: the upper incisors overlap the lower
    assert fp["9.10"][2] > fp["9.11"][2]  # in front of them
    assert 0.02 <= y["2.3"] - y["9.10"] <= 0.035  # 2-3.5 mm of upper incisor show once the lips part
    assert fp["4.1"][0] < fp["4.3"][0] < fp["4.5"][0]  # the brow runs outward
    assert fp["4.5"][0] < fp["10.9"][0]  # and ends in front of the ear
    assert fp["3.11"][0] < fp["3.5"][0] < fp["3.7"][0]
    assert fp["2.4"][0] < fp["8.3"][0]  # inner lip corner inside the outer one


def test_fapu_values(face):
    fapu = face.fapu
    assert set(fapu) == {"IRISD0", "ES0", "ENS0", "MNS0", "MW0", "AU"}
    assert fapu["AU"] == 1e-5
    for name in ("IRISD0", "ES0", "ENS0", "MNS0", "MW0"):
        assert fapu[name] > 0, name
    assert 0.55 < fapu["ES0"] * 1024 < 0.7  # eye separation ~6 cm in decimetres
    assert 0.4 < fapu["MW0"] * 1024 < 0.7  # mouth width
    assert 0.07 < fapu["IRISD0"] * 1024 < 0.14  # lid opening at the pupil
    assert 0.4 < fapu["ENS0"] * 1024 < 0.6
    assert 0.12 < fapu["MNS0"] * 1024 < 0.25
    assert fapu["ES0"] == pytest.approx((face.feature_points["3.5"][0] - face.feature_points["3.6"][0]) / 1024)


def test_fapu_names_missing_feature_points(tmp_path):
    plain = load_face(write_obj(tmp_path / "plain.obj", CUBE_V, CUBE_F))
    with pytest.raises(MissingFeaturePointsError) as err:
        _ = plain.fapu
    assert "3.1" in str(err.value) and "8.4" in str(err.value)
    assert "3.5" in err.value.missing


def test_pupils_are_the_eyeballs_front_poles(face):
    for fid, part in (("3.5", "eye_l"), ("3.6", "eye_r")):
        centre = face.pivots[part]
        pupil = face.feature_points[fid]
        assert face.feature_vertices[fid] == face.parts[part][0]
        assert pupil[0] == centre[0] and pupil[1] == centre[1] and pupil[2] > centre[2]
        radius = np.linalg.norm(face.vertices[face.parts[part]] - centre, axis=1)
        np.testing.assert_allclose(radius, pupil[2] - centre[2], rtol=1e-9)
    assert face.pivots["eye_l"][0] > 0  # eye_l is the face's own left, +x


def test_pivots_and_contours(face):
    assert set(face.pivots) >= {"eye_l", "eye_r", "jaw", "head", "jaw_axis"}
    np.testing.assert_allclose(face.pivots["jaw_axis"], [1, 0, 0])
    np.testing.assert_allclose(face.pivots["head"], face.feature_points["7.1"])
    skin = np.zeros(len(face.vertices), dtype=bool)
    skin[face.parts["skin"]] = True
    t = face.triangles
    edges = set(map(tuple, np.sort(np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1).tolist()))
    for name in ("mouth_opening", "vermilion_border", "left_lid_opening", "right_lid_opening",
                 "left_outer_eyelid", "right_outer_eyelid", "face_oval", "neck_cut"):
        loop = face.contours[name]
        assert skin[loop].all() and len(set(loop.tolist())) == len(loop), name
        for a, b in zip(loop.tolist(), np.roll(loop, -1).tolist()):  # a closed loop of mesh edges
            assert (min(a, b), max(a, b)) in edges, name
    mouth = face.contours["mouth_opening"].tolist()
    for fid in ("2.2", "2.3", "2.4", "2.5"):
        assert face.feature_vertices[fid] in mouth


def test_skin_is_closed_except_at_the_neck(face):
    tri = part_triangles(face, "skin")
    edges = np.sort(np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    assert count.max() == 2  # manifold
    boundary = set(unique[count == 1].ravel().tolist())
    assert boundary == set(face.contours["neck_cut"].tolist())
    assert face.vertices[list(boundary), 1].max() < face.feature_points["2.1"][1] - 0.1
    for part in ("eye_l", "eye_r", "tongue"):
        t = part_triangles(face, part)
        e = np.sort(np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
        assert np.all(np.unique(e, axis=0, return_counts=True)[1] == 2), part


def test_open_mouth_is_not_see_through(face):
    """Open the jaw 15 degrees (lower teeth, tongue and the skin below the lips' meeting line,
    roughly) and look into the mouth from the front: every ray through the opening must stop on
    the mouth's inside, teeth or tongue, seen from the front (the outward side of the surface),
    never on the back of the head's skin seen from inside."""
    v = face.vertices.copy()
    pivot, axis = face.pivots["jaw"], face.pivots["jaw_axis"]
    cut_y = lip_line(face, v[:, 0])
    lower = np.zeros(len(v), dtype=bool)
    skin = face.parts["skin"]
    p = v[skin]
    lower[skin] = (p[:, 1] < cut_y[skin]) & (np.abs(p[:, 0]) < 0.3) & (p[:, 2] > 0.7) & (p[:, 1] > 6.0)
    walls = lips_closed()  # the closed lips' inner walls overlap across the line: each goes with its lip
    lower[walls["upper"]], lower[walls["lower"]] = False, True
    lower[face.parts["teeth_lower"]] = True
    lower[face.parts["tongue"]] = True
    angle = np.radians(15)
    c, s = np.cos(angle), np.sin(angle)
    assert np.allclose(axis, [1, 0, 0])
    q = v[lower] - pivot
    v[lower] = pivot + np.stack([q[:, 0], c * q[:, 1] - s * q[:, 2], s * q[:, 1] + c * q[:, 2]], axis=1)
    top = face.vertices[face.feature_vertices["2.2"], 1] - 0.03
    bottom = v[face.feature_vertices["2.3"], 1] + 0.03
    assert top - bottom > 0.1  # the mouth is open
    xs, ys = np.meshgrid(np.linspace(-0.12, 0.12, 7), np.linspace(bottom, top, 6))
    origins = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, 3.0)], axis=1)
    direction = np.array([0.0, 0.0, -1.0])
    dist, tri = first_hits(origins, direction, v, face.triangles)
    assert np.all(tri >= 0), "a ray through the open mouth hit nothing"
    hit_z = 3.0 - dist
    assert np.all(hit_z < face.feature_points["2.3"][2] - 0.02)  # inside the mouth, behind the lips
    a, b, c3 = (v[face.triangles[tri, k]] for k in range(3))
    normals = np.cross(b - a, c3 - a)
    assert np.all(normals @ direction < 0), "a ray saw a surface from behind (the mouth is open at the back)"
    owner = np.empty(len(v), dtype=object)
    for name, idx in face.parts.items():
        owner[idx] = name
    assert set(owner[face.triangles[tri, 0]]) <= {"skin", "teeth_upper", "teeth_lower", "tongue"}


def test_teeth_and_tongue_sit_inside_the_mouth(face):
    """Every teeth and tongue vertex lies in the mouth cavity: rays from it in six directions
    all meet the skin (the cavity is enclosed by the closed lips). The incisal edges sit at the
    height of the lips' meeting line (so they show as soon as the lips part): the ones there are
    sampled too, since the lips are closed at rest and no ray leaves between them."""
    skin_tri = part_triangles(face, "skin")
    idx = np.concatenate([face.parts["teeth_upper"], face.parts["teeth_lower"], face.parts["tongue"]])
    slit = face.vertices[face.contours["mouth_opening"], 1]
    y = face.vertices[idx, 1]
    band = idx[(y > slit.min() - 0.005) & (y < slit.max() + 0.005)]
    rng = np.random.default_rng(0)
    sample = face.vertices[np.concatenate([rng.choice(idx, 60, replace=False), band])]
    for direction in np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0.0, 0.0, -1]]):
        _, tri = first_hits(sample, direction.astype(float), face.vertices, skin_tri)
        assert np.all(tri >= 0), direction


def test_content_hash(face):
    assert len(face.content_hash) == 64
    assert face.content_hash == load_face().content_hash
    moved = load_face()
    moved.vertices[0, 0] += 1e-6
    assert moved.content_hash != face.content_hash


def test_content_hash_follows_edits_made_after_it_was_asked():
    """The hash keys the coefficient cache on disk: an edited mesh must never get the old key."""
    edited = load_face()
    before = edited.content_hash
    rest = edited.vertices[0].copy()
    edited.vertices[0] += 1
    assert edited.content_hash != before
    edited.vertices[0] = rest
    assert edited.content_hash == before
    edited.triangles[0] = edited.triangles[0][::-1].copy()
    assert edited.content_hash != before


# -- load_face(path) ----------------------------------------------------------------------------

CUBE_V = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
CUBE_F = [(1, 4, 3, 2), (5, 6, 7, 8), (1, 2, 6, 5), (2, 3, 7, 6), (3, 4, 8, 7), (4, 1, 5, 8)]


def write_obj(path: Path, verts, faces, extra: str = "") -> Path:
    lines = ["# test mesh", "o cube"] + [f"v {x} {y} {z}" for x, y, z in verts]
    lines += [extra] if extra else []
    lines += ["f " + " ".join(str(i) for i in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_load_obj_keeps_file_vertex_order_across_uv_seams(tmp_path):
    # a cube whose six faces each have their own four UVs (24 UVs, seams on every edge), some
    # corners written with normals, one face with negative (relative) indices
    verts = [(0.3, -0.2, 0.1), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    lines = ["# cube with seams", "mtllib none.mtl", "g cube"] + [f"v {x} {y} {z}" for x, y, z in verts]
    lines += [f"vt {u / 4} {w / 4}" for u in range(4) for w in range(6)]
    lines += ["vn 0 0 1"]
    uv = iter(range(1, 25))
    for k, f in enumerate(CUBE_F[:-1]):
        corners = [f"{v}/{next(uv)}/1" if k % 2 else f"{v}/{next(uv)}" for v in f]
        lines.append("f " + " ".join(corners))
    last = [-(8 - v + 1) for v in CUBE_F[-1]]  # v = 8 is -1
    lines.append("f " + " ".join(f"{v}/{-(24 - next(uv) + 1)}" for v in last))
    path = tmp_path / "seams.obj"
    path.write_text("\n".join(lines) + "\n")

    f = load_face(path)
    assert f.name == "seams"
    np.testing.assert_array_equal(f.vertices, np.array(verts, dtype=float))
    assert len(f.triangles) == 12
    assert f.uv.shape == (24, 2) and f.triangle_uv.shape == (12, 3)
    assert f.triangles[0].tolist() == [0, 3, 2] and f.triangles[1].tolist() == [0, 2, 1]  # fan a b c, a c d
    assert f.triangles[-2].tolist() == [3, 0, 4]  # from the negative indices
    assert list(f.parts) == ["skin"] and f.parts["skin"].tolist() == list(range(8))
    assert f.feature_points == {} and f.feature_vertices == {}
    assert f.source_index is None


def test_load_obj_polygons_without_uvs(tmp_path):
    path = write_obj(tmp_path / "poly.obj", [(0, 0, 0), (1, 0, 0), (1.5, 1, 0), (0.5, 1.5, 0), (-0.5, 1, 0)],
                     [(1, 2, 3, 4, 5)], extra="vn 0 0 1")
    f = load_face(path)
    assert f.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4]]
    assert f.uv is None and f.triangle_uv is None


def test_a_bare_obj_reads_back_as_written(tmp_path):
    """write_bare_obj -> load_mesh: the same positions to the last bit, the same triangles, one skin
    part and nothing else (no colours, uv, groups or materials), as a user's bare mesh loads."""
    shipped = load_face()
    vertices = shipped.vertices + np.random.default_rng(3).normal(scale=1e-3, size=shipped.vertices.shape)
    path = write_bare_obj(tmp_path / "bare.obj", vertices, shipped.triangles)
    back = load_mesh(path)
    np.testing.assert_array_equal(back.vertices, vertices)
    np.testing.assert_array_equal(back.triangles, shipped.triangles)
    assert list(back.parts) == ["skin"] and back.parts["skin"].tolist() == list(range(len(vertices)))
    assert back.colors is None and back.uv is None and back.feature_vertices == {}
    mesh = read_obj(path)
    assert set(mesh.groups) == {None} and set(mesh.materials) == {None} and mesh.mtllibs == [] and len(mesh.uvs) == 0


def test_load_ply_and_glb_keep_vertex_order(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    rng = np.random.default_rng(1)
    v1 = rng.normal(size=(30, 3))
    f1 = rng.integers(0, 30, size=(20, 3))
    f1 = f1[(f1[:, 0] != f1[:, 1]) & (f1[:, 1] != f1[:, 2]) & (f1[:, 0] != f1[:, 2])]
    m1 = trimesh.Trimesh(v1, f1, process=False)
    ply = tmp_path / "mesh.ply"
    m1.export(ply)
    f = load_face(ply)
    np.testing.assert_allclose(f.vertices, v1, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(f.triangles, f1)
    v2 = rng.normal(size=(12, 3)) + 5
    f2 = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11]])
    scene = trimesh.Scene()
    scene.add_geometry(m1, geom_name="first")
    scene.add_geometry(trimesh.Trimesh(v2, f2, process=False), geom_name="second")
    glb = tmp_path / "scene.glb"
    scene.export(glb)
    g = load_face(glb)
    assert len(g.vertices) == 42 and len(g.triangles) == len(f1) + 4
    np.testing.assert_allclose(g.vertices[:30], v1, atol=1e-5)
    np.testing.assert_allclose(g.vertices[30:], v2, atol=1e-5)
    np.testing.assert_array_equal(g.triangles[len(f1):], f2 + 30)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.obj"):
        load_face(tmp_path / "nothere.obj")
    with pytest.raises(FileNotFoundError, match="nothere.ply"):
        load_face(tmp_path / "nothere.ply")
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 3\n")
    with pytest.raises(FaceFileError, match=r"bad\.obj:3.*out of range"):
        load_face(bad)
    junk = tmp_path / "junk.obj"
    junk.write_text("v 0 zero 0\n")
    with pytest.raises(FaceFileError, match=r"junk\.obj:1"):
        load_face(junk)
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\n")
    with pytest.raises(FaceFileError, match="no vertices"):
        load_face(empty)
    garbage = tmp_path / "garbage.ply"
    garbage.write_bytes(b"\x00\x01 not a ply file")
    with pytest.raises(FaceFileError, match="garbage.ply"):
        load_face(garbage)
    with pytest.raises(FaceFileError, match="face folder .* has no face.obj"):  # a folder is a face folder
        load_face(tmp_path)


# -- the builder --------------------------------------------------------------------------------

@needs_shared
def test_builder_reproduces_the_shipped_face(tmp_path):
    out = tmp_path / "data"
    subprocess.run([sys.executable, str(REPO / "tools" / "builders" / "build_default_face.py"), "--out", str(out)],
                   check=True, capture_output=True, cwd=REPO)
    shipped = REPO / "puppet" / "data"
    with np.load(shipped / "default_face.npz") as a, np.load(out / "default_face.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:  # floats to the last bits numpy's own build may round otherwise (1e-14)
            assert a[key].dtype == b[key].dtype, key
            if a[key].dtype.kind == "f":
                np.testing.assert_allclose(a[key], b[key], rtol=0, atol=1e-12, err_msg=key)
            else:
                np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert json.loads((out / "default_face.json").read_text()) == json.loads((shipped / "default_face.json").read_text())
    for name in ("PROVENANCE.md", "LICENSE-CC0.md"):
        assert (out / name).read_bytes() == (shipped / name).read_bytes(), name


def test_shipped_data_files():
    data = REPO / "puppet" / "data"
    assert (data / "default_face.npz").stat().st_size < 3_000_000
    assert "MakeHuman" in (data / "PROVENANCE.md").read_text() and "CC0" in (data / "PROVENANCE.md").read_text()
    assert "CC0" in (data / "LICENSE-CC0.md").read_text()
    meta = json.loads((data / "default_face.json").read_text())
    assert meta["units"] == "decimetre"
    assert set(meta["feature_points"]) == set(load_face().feature_points)
