"""The texture of a face from one photo: the photo where it shows the face, the performer's own
skin colour everywhere else, with no seam between them.

Each vertex takes the photo's pixel where the face *as photographed* puts it (``uv``: the face
posed with the photo's expression and turned as the head was, through the fitted camera), so
the lips take the photo's lips even when the neutral face has closed the mouth the photo shows
open. The photo is prepared first (``texture_face``):

* its baked lighting is evened out (``even_lighting``): the colour of the skin (a mask of the
  face below the forehead, less eyes, brows, lips, nostrils and what is not skin-coloured),
  smoothed by a normalised Gaussian, is brought to its median channel by channel, so a shadow
  beside the nose or a darker, warmer side of the face no longer sits in the texture; that
  median is the skin colour;
* what is neither skin nor a feature (hair, clothes, background) is painted with the skin
  colour, and the mouth opening (teeth, the dark inside) with the lips' colour
  (``_paint_mouth``): whatever the texture reaches at the face's edge is skin, and at the lips'
  inner edge lip, never teeth.

A per-vertex weight says how much of the photo shows over the vertex colour (``puppet.view.renderer``
mixes the two per pixel; ``photo_weight``): the skin inside the face's outline, fading out across
a band at the outline, as the surface turns from the camera, above the brows (the hairline is the
skin's: the head is bald) and at the mouth opening; the eyeballs inside the lid openings; nothing
on the teeth, tongue and mouth (they keep the face's own materials).

The vertex colours (``_skin_colors``) take the photo's colour (blurred) wherever the photo shows
at all, so the two agree where it fades out, and carry it smoothly (harmonic on the mesh) round
the sides, back and neck to the skin colour on the back of the head; the default face's lips,
brows and lash lines keep their difference from its skin.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from PIL import Image, ImageDraw
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

from puppet.face.folder import TexturedFace
from puppet.face.model import Face
from puppet.photo.depth import PhotoCamera, face_width
from puppet.runtime.normals import VertexNormals

TEXTURE_MAX = 1024  # longest side of texture.png, pixels
OVAL_BAND = 0.10  # fade-out band inside the face outline, fraction of the face's width
FACING = (0.25, 0.6)  # cosine toward the camera over which the photo fades in
MOUTH_BAND = 0.025  # fade band outside the photo's mouth opening, fraction of the face's width
SHADING_SIGMA = 0.1  # the smoothing of the photo's shading, fraction of the face's width
GAIN_RANGE = (0.7, 1.5)  # how far evening may darken or brighten the photo
EVEN_PASSES = 2  # evening passes (``even_lighting``)
FOREHEAD_FADE = (0.15, 0.6)  # of the way from the brows to the outline's top: the photo fades out
SKIN_DISTANCE = 0.09  # chromaticity distance from the cheeks' colour at which skin likeness is 1/e
SKIN_LIKENESS = 0.2  # the likeness at which a pixel counts as skin
FEATURE_GROW = 0.03  # eyes, brows, lips and nostrils are kept this far around, fraction of the width
EDGE_BLUR = 0.02  # the photo's colour a vertex's colour takes is blurred by this fraction of the width
TONE_RADIUS = 0.08  # the face's broad colour is its colour averaged over this fraction of its width
MOUTH_GROW = 0.03  # the mouth opening painted over is grown by this fraction of the width (a line of it round
# the edge): the face as photographed runs through the landmarks, but between them its opening may sit
# a pixel or two off the photo's
PAINT_BLUR = 0.015  # the edge between kept photo and painted skin is softened over this fraction


def texture_face(face: Face, shown: np.ndarray, camera: PhotoCamera, photo: np.ndarray,
                 name: str = "photo") -> tuple[TexturedFace, dict]:
    """``face`` (the neutral face) textured by ``photo`` (H, W, 3 uint8): ``shown`` (N, 3) are
    its vertices as photographed (posed, in the photo frame of ``camera``). Returns the face and
    a report (skin tone, textured vertices, texture size)."""
    pixels = camera.project(shown)
    width = float(np.ptp(pixels[face.contours["face_oval"], 0]))
    features = _feature_mask(face, pixels, photo.shape[:2], width)
    skin = _skin_mask(face, pixels, photo, features)
    evened, tone = even_lighting(photo, skin, SHADING_SIGMA * width)
    keep = gaussian_filter((skin | features).astype(float), PAINT_BLUR * width)[..., None]
    painted = np.round(keep * evened + (1.0 - keep) * 255 * tone).astype(np.uint8)
    _paint_mouth(painted, face, pixels, width)
    crop, box = _crop(painted, pixels)
    x0, y0, x1, y1 = box
    uv = np.c_[(pixels[:, 0] - x0) / (x1 - x0), 1.0 - (pixels[:, 1] - y0) / (y1 - y0)]
    inside = ((uv >= 0) & (uv <= 1)).all(axis=1)
    weight = photo_weight(face, shown, camera.focal, pixels, width) * inside
    edge = _sample(gaussian_filter(painted.astype(float) / 255.0, (EDGE_BLUR * width, EDGE_BLUR * width, 0)), pixels)
    report = {"skin_tone": [round(float(c), 4) for c in tone], "textured_vertices": int((weight > 0).sum()),
              "texture_size": [int(crop.shape[1]), int(crop.shape[0])], "source_photo": name}
    return TexturedFace(name=name, vertices=face.vertices, triangles=face.triangles, parts=face.parts,
                        feature_points=face.feature_points, feature_vertices=face.feature_vertices,
                        pivots=face.pivots, contours=face.contours, colors=_skin_colors(face, weight, edge, tone),
                        uv=np.clip(uv, 0.0, 1.0).astype(np.float32), triangle_uv=face.triangles.copy(),
                        source_index=face.source_index, texture=crop,
                        texture_weight=weight.astype(np.float32)), report


def photo_weight(face: Face, shown: np.ndarray, focal: float, pixels: np.ndarray, width: float) -> np.ndarray:
    """Per-vertex photo weight (module docstring); ``width`` is the face's width in pixels."""
    normals = VertexNormals(face.triangles, len(shown))(shown)
    toward = np.array([0.0, 0.0, focal]) - shown
    facing = (normals * toward).sum(axis=1) / np.linalg.norm(toward, axis=1)
    facing = np.clip((facing - FACING[0]) / (FACING[1] - FACING[0]), 0.0, 1.0)
    weight = np.zeros(len(shown))
    skin = face.parts["skin"]
    oval = pixels[face.contours["face_oval"]]
    within = np.clip(_inside_distance(oval, pixels[skin]) / (OVAL_BAND * width), 0.0, 1.0)
    mouth = pixels[face.contours["mouth_opening"]]
    lips = np.clip(-_inside_distance(mouth, pixels[skin]) / (MOUTH_BAND * width), 0.0, 1.0)
    rise = _rise(face, skin)
    forehead = np.clip((FOREHEAD_FADE[1] - rise) / (FOREHEAD_FADE[1] - FOREHEAD_FADE[0]), 0.0, 1.0)
    weight[skin] = facing[skin] * within * lips * forehead
    for eye, loop in (("eye_l", "left_lid_opening"), ("eye_r", "right_lid_opening")):
        ix = face.parts[eye]
        lid = pixels[face.contours[loop]]
        inside = np.clip(_inside_distance(lid, pixels[ix]) / (0.1 * np.ptp(lid[:, 0])), 0.0, 1.0)
        weight[ix] = inside * (facing[ix] > 0)
    return weight


def _rise(face: Face, rows: np.ndarray) -> np.ndarray:
    """How far vertices are above the brows, as a fraction of the way to the face outline's top."""
    brows = np.mean([face.feature_points[f"4.{k}"][1] for k in range(1, 7)])
    top = face.vertices[face.contours["face_oval"], 1].max()
    return (face.vertices[rows, 1] - brows) / max(top - brows, 1e-9)


def skin_likeness(colour: np.ndarray, tone: np.ndarray) -> np.ndarray:
    """How much colours (..., 3, 0-1) look like the skin colour ``tone`` (3,) in chromaticity
    (shading changes a colour's brightness, not its chromaticity): 1 at it, falling away."""
    colour = np.asarray(colour, float)
    chroma = colour / np.maximum(colour.sum(axis=-1, keepdims=True), 1e-6)
    distance = 3.0 * np.linalg.norm(chroma - tone / max(tone.sum(), 1e-6), axis=-1)
    return np.exp(-(distance / SKIN_DISTANCE) ** 2)


def even_lighting(photo: np.ndarray, mask: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """(the photo with its shading over the skin divided out, as uint8; the skin colour 0-1):
    the skin's colour under ``mask``, smoothed by a normalised Gaussian of ``sigma`` pixels, is
    brought to its median everywhere, channel by channel (a warm shadow is evened as well as a
    dark one; within ``GAIN_RANGE``). It is done ``EVEN_PASSES`` times: near the mask's edge the
    smoothed colour leans on the skin inside, so one pass leaves the shaded sides a little dark."""
    image = photo[..., :3].astype(float) / 255.0
    m = mask.astype(float)[..., None]
    weight = np.maximum(gaussian_filter(m, (sigma, sigma, 0)), 1e-6)
    reach = np.clip(gaussian_filter(m, (2 * sigma, 2 * sigma, 0)) * 4.0, 0.0, 1.0)  # not far from the face
    gain = np.ones_like(image)
    for _ in range(EVEN_PASSES):
        evened = image * gain
        shading = gaussian_filter(evened * m, (sigma, sigma, 0)) / weight
        change = np.median(evened[mask], axis=0) / np.maximum(shading, 1e-6)
        gain = np.clip(gain * (1.0 + reach * (change - 1.0)), *GAIN_RANGE)
    evened = np.clip(image * gain, 0.0, 1.0)
    return np.round(evened * 255).astype(np.uint8), np.median(evened[mask], axis=0)


def _paint_mouth(image: np.ndarray, face: Face, pixels: np.ndarray, width: float) -> None:
    """Paint the photo's mouth opening (teeth, tongue, the dark inside; grown a little) with the
    median colour of its lips, in place: whatever the lips' texture reaches past their inner
    edge is lip, never teeth."""
    shape = image.shape[:2]
    lips, mouth = (Image.new("L", (shape[1], shape[0]), 0) for _ in range(2))
    ImageDraw.Draw(lips).polygon([tuple(p) for p in pixels[face.contours["vermilion_border"]]], fill=255)
    ring = [tuple(p) for p in pixels[face.contours["mouth_opening"]]]
    draw = ImageDraw.Draw(mouth)
    draw.polygon(ring, fill=255)
    draw.line(ring + ring[:1], fill=255, width=max(1, round(MOUTH_GROW * width)))
    inside = np.asarray(mouth) > 0
    lip = (np.asarray(lips) > 0) & ~inside
    if lip.any():
        image[inside] = np.median(image[lip], axis=0)


def _feature_mask(face: Face, pixels: np.ndarray, shape: tuple[int, int], width: float) -> np.ndarray:
    """Photo pixels of the eyes, brows, lips and nostrils, grown by ``FEATURE_GROW``: kept as
    the photo shows them, whatever their colour."""
    image = Image.new("L", (shape[1], shape[0]), 0)
    draw = ImageDraw.Draw(image)
    grow = max(2, round(FEATURE_GROW * width))
    for loop in ("left_lid_opening", "right_lid_opening", "vermilion_border"):
        ring = [tuple(p) for p in pixels[face.contours[loop]]]
        draw.polygon(ring, fill=255)
        draw.line(ring + ring[:1], fill=255, width=2 * grow)
    fp = face.feature_vertices
    for brow in (("4.6", "4.4", "4.2"), ("4.1", "4.3", "4.5")):
        draw.line([tuple(pixels[fp[k]]) for k in brow], fill=255, width=3 * grow)
    for nostril in ("9.1", "9.2"):
        x, y = pixels[fp[nostril]]
        draw.ellipse((x - grow, y - grow, x + grow, y + grow), fill=255)
    return np.asarray(image) > 0


def _skin_mask(face: Face, pixels: np.ndarray, photo: np.ndarray, features: np.ndarray) -> np.ndarray:
    """Photo pixels of bare skin: inside the face's outline below the forehead's fade, not a
    feature, and near the cheeks' colour in chromaticity (not hair, clothes or background)."""
    image = Image.new("L", (photo.shape[1], photo.shape[0]), 0)
    oval = np.asarray(face.contours["face_oval"])
    ImageDraw.Draw(image).polygon([tuple(p) for p in pixels[oval[_rise(face, oval) <= FOREHEAD_FADE[0]]]], fill=255)
    fp = face.feature_vertices
    width = float(np.ptp(pixels[oval, 0]))
    seed = np.median(photo[_disc(photo.shape[:2], pixels[[fp["5.1"], fp["5.2"]]], max(2.0, 0.06 * width))][:, :3], axis=0)
    return (np.asarray(image) > 0) & ~features & (skin_likeness(photo[..., :3] / 255.0, seed / 255.0) > SKIN_LIKENESS)


def _disc(shape: tuple[int, int], centres: np.ndarray, radius: float) -> np.ndarray:
    rows, cols = np.mgrid[:shape[0], :shape[1]]
    near = np.zeros(shape, bool)
    for cx, cy in centres:
        near |= (cols - cx) ** 2 + (rows - cy) ** 2 <= radius ** 2
    return near


def _crop(photo: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The photo cut to the projected head (plus 5%) inside the image, scaled down to at most
    ``TEXTURE_MAX``; and the box (x0, y0, x1, y1) in photo pixels it covers."""
    height, width = photo.shape[:2]
    lo, hi = pixels.min(axis=0), pixels.max(axis=0)
    pad = 0.05 * (hi - lo)
    x0, y0 = (int(np.clip(np.floor(c), 0, m)) for c, m in zip(lo - pad, (width - 1, height - 1)))
    x1, y1 = (int(np.clip(np.ceil(c), lo_ + 1, m)) for c, m, lo_ in zip(hi + pad, (width, height), (x0, y0)))
    crop = Image.fromarray(photo[y0:y1, x0:x1])
    factor = min(1.0, TEXTURE_MAX / max(crop.size))
    if factor < 1.0:
        crop = crop.resize((max(1, round(crop.width * factor)), max(1, round(crop.height * factor))), Image.LANCZOS)
    return np.asarray(crop), (x0, y0, x1, y1)


def _inside_distance(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (M,) of 2D points to a closed polygon's edges, negative outside it."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    ab = b - a
    t = np.clip(((points[:, None] - a) * ab).sum(-1) / (ab ** 2).sum(-1), 0.0, 1.0)
    d = np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=-1).min(axis=1)
    return np.where(_contains(polygon, points), d, -d)


def _contains(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Even-odd rule: (M,) True for 2D points inside the closed polygon."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    x, y = points[:, None, 0], points[:, None, 1]
    spans = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        cross_x = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (spans & (x < cross_x)).sum(axis=1) % 2 == 1


def _skin_colors(face: Face, weight: np.ndarray, edge: np.ndarray, tone: np.ndarray) -> np.ndarray:
    """The vertex colours: the skin's broad colour is the photo's (``edge``: the painted photo,
    blurred, at each vertex) wherever the photo shows at all, so the two agree where the photo
    fades out; from there it flows smoothly (harmonic on the mesh) to the skin colour ``tone``
    on the back of the head. Each skin vertex keeps its ratio to the face's own colour around it
    (``TONE_RADIUS``), so lips, brows and lash lines stay as the face has them."""
    colors = np.array(face.colors if face.colors is not None else np.full((len(face.vertices), 3), 0.7), np.float32)
    skin = face.parts["skin"]
    v = face.vertices[skin]
    seen = weight[skin] > 0
    back = v[:, 2] < face.pivots["head"][2]
    fixed = seen | back
    base = np.where(seen[:, None], edge[skin], tone)
    adjacency = _adjacency(face.triangles, skin)
    laplacian = sp.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency
    free = ~fixed
    if free.any():
        A = laplacian[free][:, free].tocsc()
        base[free] = spla.spsolve(A, -laplacian[free][:, fixed] @ base[fixed]).reshape(-1, 3)
    radius = TONE_RADIUS * face_width(face)
    near = cKDTree(v).sparse_distance_matrix(cKDTree(v), 2.5 * radius, output_type="coo_matrix")
    kernel = sp.csr_matrix((np.exp(-(near.data / radius) ** 2), (near.row, near.col)), shape=near.shape)
    around = (kernel @ colors[skin]) / np.asarray(kernel.sum(axis=1))
    colors[skin] = np.clip(colors[skin] / np.maximum(around, 1e-3) * base, 0.0, 1.0)
    return colors


def _adjacency(triangles: np.ndarray, rows: np.ndarray) -> sp.csr_matrix:
    """The edge graph (0/1, symmetric) of the mesh restricted to the vertices ``rows``."""
    index = np.full(int(triangles.max()) + 1, -1)
    index[rows] = np.arange(len(rows))
    t = index[triangles]
    t = t[(t >= 0).all(axis=1)]
    i = np.concatenate([t[:, 0], t[:, 1], t[:, 2]])
    j = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
    graph = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(len(rows), len(rows)))
    graph = graph + graph.T
    graph.data[:] = 1.0
    return graph


def _sample(image: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """The image's value at each pixel position (nearest pixel, clamped to the image)."""
    h, w = image.shape[:2]
    cols = np.clip(np.round(pixels[:, 0]).astype(int), 0, w - 1)
    rows = np.clip(np.round(pixels[:, 1]).astype(int), 0, h - 1)
    return image[rows, cols]
