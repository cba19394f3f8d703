"""Build ``puppet/data/mediapipe_map.json``: where each of MediaPipe Face Mesh's 468 landmarks
sits on the default face, as a point on one of its skin triangles (three vertices, barycentric
weights).

The detector itself says where: the default face is rendered from the front and a little turned
(``VIEWS``), MediaPipe finds its landmarks in each image (``puppet.photo.detect``, the photo
environment), and each landmark's pixel is cast back as a ray onto the face's outer skin; the
hits of the views are averaged (weighted by how squarely the skin faces the camera) and put back
on the surface. So a photo's landmarks are matched with the points where MediaPipe puts them on
this face, whatever its conventions (the forehead's top, the outline on the cheeks). The
landmarks along the lips' meeting line, the vermilion border and the lid margins are put on the
default face's own contours (the nearest point of the right lip or lid), where a ray may slip
into the slit between the lips.

Needs the photo environment (tools/setup.sh) and an OpenGL context (EGL).
Run: PYTHONPATH=. .venv/bin/python tools/builders/build_mediapipe_map.py
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.photo.build import MEDIAPIPE_FDP, _topology_hash
from puppet.photo.detect import detect_landmarks
from puppet.photo.texture import _inside_distance
from puppet.runtime.normals import VertexNormals
from puppet.view.renderer import Renderer, save_png

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "puppet" / "data" / "mediapipe_map.json"
SIZE = 1024
VIEWS = [(0, 0), (-15, 0), (15, 0), (0, -10), (0, 10), (-8, 6), (8, 6), (-8, -6), (8, -6)]
"""(yaw, pitch) degrees of the camera about the head; the first is the front view."""
OVAL = [10, 338, 297, 332, 284, 251, 389, 356, 454, 323, 361, 288, 397, 365, 379, 378, 400, 377, 152, 148,
        176, 149, 150, 136, 172, 58, 132, 93, 234, 127, 162, 21, 54, 103, 67, 109]
"""MediaPipe's face outline."""

# MediaPipe chains along a contour of the default face, corner to corner through the middle.
CHAINS = {
    "mouth_opening": [[78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308],
                      [78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308]],
    "vermilion_border": [[61, 185, 40, 39, 37, 0, 267, 269, 270, 409, 291],
                         [61, 146, 91, 181, 84, 17, 314, 405, 321, 375, 291]],
    "right_lid_opening": [[33, 246, 161, 160, 159, 158, 157, 173, 133],
                          [33, 7, 163, 144, 145, 153, 154, 155, 133]],
    "left_lid_opening": [[263, 466, 388, 387, 386, 385, 384, 398, 362],
                         [263, 249, 390, 373, 374, 380, 381, 382, 362]],
}


def outer_skin(face: Face) -> np.ndarray:
    """Skin triangles (rows of ``face.triangles``) that are not behind the mouth or lid openings."""
    skin = face.parts["skin"]
    tris = face.triangles[np.isin(face.triangles, skin).all(axis=1)]
    centres = face.vertices[tris].mean(axis=1)
    behind = np.zeros(len(tris), bool)
    for name in ("mouth_opening", "left_lid_opening", "right_lid_opening"):
        loop = face.vertices[face.contours[name]]
        near = _inside_distance(loop[:, :2], centres[:, :2]) > -0.02
        behind |= near & (centres[:, 2] < loop[:, 2].min())
    return tris[~behind]


def cast(origin: np.ndarray, directions: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The nearest hit (M, 3) of rays from ``origin`` along ``directions`` (M, 3) on triangles
    (F, 3, 3) and its triangle (M,), -1 where a ray misses (Moller-Trumbore)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2 = b - a, c - a
    hits, which = np.zeros((len(directions), 3)), np.full(len(directions), -1)
    for m, d in enumerate(directions):
        p = np.cross(d, e2)
        det = (e1 * p).sum(axis=1)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = origin - a
        u = (s * p).sum(axis=1) * inv
        q = np.cross(s, e1)
        v = (q @ d) * inv
        t = (q * e2).sum(axis=1) * inv
        good = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if good.any():
            k = np.flatnonzero(good)[np.argmin(t[good])]
            hits[m], which[m] = origin + t[k] * d, k
    return hits, which


def detected_on_surface(renderer: Renderer, vertices: np.ndarray, tris: np.ndarray, framed: np.ndarray,
                        margin: float, work: Path) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Where MediaPipe finds its landmarks on a surface (the triangles ``tris`` of a mesh drawn
    by ``renderer`` at ``vertices``), seen from ``VIEWS`` about the front view framing
    ``framed``: per landmark, the facing-weighted mean of its cast hits (468, 3) (the front
    view's hit alone for the face outline, a silhouette that moves as the head turns), the
    weight each got (468,), and the front view's detected pixels with the mesh's vertices
    projected in it: ((468, 2), (N, 2))."""
    total, weight = np.zeros((468, 3)), np.zeros(468)
    corners = vertices[tris]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    used = np.unique(tris)
    front = renderer.aim(framed, view="front", margin=margin)
    toward = front.eye - vertices[used]
    facing = (VertexNormals(tris, len(vertices))(vertices)[used] * toward).sum(axis=1) / np.linalg.norm(toward, axis=1)
    rim = used[facing > -0.2]  # facing the front camera or side-on: the silhouette is among them
    distance = np.linalg.norm(front.eye - front.target)
    size = renderer.size
    for yaw, pitch in VIEWS:
        y, p = np.radians(yaw), np.radians(pitch)
        direction = np.array([np.sin(y) * np.cos(p), np.sin(p), np.cos(y) * np.cos(p)])
        camera = renderer.look_at(front.target + distance * direction, front.target, fov=front.fov)
        path = work / f"view_{yaw}_{pitch}.png"
        save_png(renderer.render(vertices), path)
        pixels = np.array(detect_landmarks(path)["points"])[:468, :2]
        if (yaw, pitch) == (0, 0):
            front_pixels, projected = pixels, renderer.project(vertices)
        right, up, back = camera.basis()
        tan = np.tan(np.radians(camera.fov) / 2)
        x, yy = (2 * pixels[:, 0] / size[0] - 1) * tan * size[0] / size[1], (1 - 2 * pixels[:, 1] / size[1]) * tan
        rays = -back + x[:, None] * right + yy[:, None] * up
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        hits, which = cast(camera.eye, rays, corners)
        w = np.where(which >= 0, np.clip(-(normals[which] * rays).sum(axis=1), 0.0, 1.0) ** 2, 0.0)
        if (yaw, pitch) != (0, 0):
            w[OVAL] = 0.0
        else:  # a point just off the silhouette or in a hole: the rim's vertex shown nearest it
            for m in np.flatnonzero(which < 0):
                hits[m] = vertices[rim[np.argmin(np.linalg.norm(projected[rim] - pixels[m], axis=1))]]
                w[m] = 1.0
        total += w[:, None] * hits
        weight += w
    renderer.aim(framed, view="front", margin=margin)
    return total / np.maximum(weight, 1e-12)[:, None], weight, (front_pixels, projected)


def closest_on(triangles: np.ndarray, points: np.ndarray, candidates: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """The closest point (M, 3) on triangles (F, 3, 3) to each point, and its triangle (M,),
    searched among the triangles with the nearest centroids."""
    _, near = cKDTree(triangles.mean(axis=1)).query(points, k=candidates)
    repeated = np.repeat(points, candidates, axis=0)
    pairs = trimesh.triangles.closest_point(triangles[near.ravel()], repeated)
    distance = np.linalg.norm(pairs - repeated, axis=1).reshape(-1, candidates)
    best = distance.argmin(axis=1)
    rows = np.arange(len(points))
    return pairs.reshape(-1, candidates, 3)[rows, best], near[rows, best]


def barycentric(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Barycentric weights (M, 3) of points (M, 3) in triangles (M, 3, 3), clipped inside."""
    w = np.clip(trimesh.triangles.points_to_barycentric(corners, points), 0.0, 1.0)
    return w / w.sum(axis=1, keepdims=True)


def on_contour(face: Face, contour: str, chain: list[int], front: tuple[np.ndarray, np.ndarray]) -> list[tuple[int, int, int, float]]:
    """(landmark, vertex a, vertex b, weight of b): each chain entry on the contour's path from
    the chain's first feature point to its last (the upper or lower lip or lid), keys on their
    feature vertex, the rest where the path passes nearest the landmark in the front view."""
    pixels, projected = front
    loop = list(face.contours[contour])
    ends = [loop.index(face.feature_vertices[MEDIAPIPE_FDP[chain[k]]]) for k in (0, -1)]
    middle = face.feature_vertices[MEDIAPIPE_FDP[chain[len(chain) // 2]]]
    n = len(loop)
    path = [loop[(ends[0] + s) % n] for s in range((ends[1] - ends[0]) % n + 1)]
    if middle not in path:
        path = [loop[(ends[0] - s) % n] for s in range((ends[0] - ends[1]) % n + 1)]
    p = projected[path]
    seg = p[1:] - p[:-1]
    out = []
    for landmark in chain:
        if landmark in MEDIAPIPE_FDP:
            vertex = face.feature_vertices[MEDIAPIPE_FDP[landmark]]
            out.append((landmark, vertex, vertex, 0.0))
            continue
        t = np.clip(((pixels[landmark] - p[:-1]) * seg).sum(axis=1) / (seg ** 2).sum(axis=1), 0.0, 1.0)
        s = int(np.argmin(np.linalg.norm(p[:-1] + t[:, None] * seg - pixels[landmark], axis=1)))
        out.append((landmark, path[s], path[s + 1], float(t[s])))
    return out


def main() -> int:
    face = load_face()
    tris = outer_skin(face)
    with tempfile.TemporaryDirectory() as work, Renderer.for_face(face, width=SIZE, height=SIZE) as renderer:
        found, weight, front = detected_on_surface(renderer, face.vertices, tris, face.vertices[face.parts["skin"]],
                                                   1.3, Path(work))
    if (weight == 0).any():
        print(f"landmarks never found on the face: {np.flatnonzero(weight == 0).tolist()}")
        return 1
    closest, tri = closest_on(face.vertices[tris], found)
    corners = tris[tri]
    weights = barycentric(closest, face.vertices[corners])
    for contour, chains in CHAINS.items():
        for chain in chains:
            for landmark, a, b, t in on_contour(face, contour, chain, front):
                corners[landmark] = (a, b, a)
                weights[landmark] = (1.0 - t, t, 0.0)
    text = {"about": "MediaPipe Face Mesh landmark i (0-467) on the default face: three vertices and "
                     "barycentric weights; built by tools/builders/build_mediapipe_map.py from MediaPipe's own "
                     "detections on renders of the default face",
            "vertex_count": len(face.vertices), "face_hash": _topology_hash(face),
            "vertices": corners.tolist(), "weights": np.round(weights, 6).tolist()}
    OUT.write_text(json.dumps(text, separators=(",", ":")) + "\n", encoding="utf-8")
    print(f"{OUT}: 468 landmarks from {len(VIEWS)} views")
    return 0


if __name__ == "__main__":
    sys.exit(main())
