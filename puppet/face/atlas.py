"""One texture from several: the base-colour images of a face's pieces packed side by side.

The renderer draws a face with one albedo texture, per-vertex uv and a per-vertex texture weight
(``puppet.view.renderer``); a file whose pieces carry textures of their own (skin, eyes, teeth)
keeps that one-texture path, and so its per-frame cost, by packing the images into an atlas and
moving each piece's uv into its image's place. Images sit left to right along the top, each at its
own size; the atlas is at most ``MAX_SIDE`` wide, all images scaled down alike when they would not
fit. A uv outside 0-1 (a repeating texture) is clamped to the image's edge: an atlas cannot repeat
one of its images.
"""

from __future__ import annotations

import numpy as np
from PIL import Image

MAX_SIDE = 8192


def pack(images: list[np.ndarray]) -> tuple[np.ndarray, list[tuple[float, float, float, float]]]:
    """(atlas (H, W, 3) uint8, per image its (u0, v0, du, dv) place in atlas uv, v up as in OBJ)."""
    scale = min(1.0, MAX_SIDE / sum(im.shape[1] for im in images), MAX_SIDE / max(im.shape[0] for im in images))
    if scale < 1.0:
        images = [_resized(im, scale) for im in images]
    width, height = sum(im.shape[1] for im in images), max(im.shape[0] for im in images)
    atlas = np.zeros((height, width, 3), dtype=np.uint8)
    places, x = [], 0
    for im in images:
        h, w = im.shape[:2]
        atlas[:h, x:x + w] = im[:, :, :3]
        places.append((x / width, 1.0 - h / height, w / width, h / height))
        x += w
    return atlas, places


def place_uv(uv_down: np.ndarray, place: tuple[float, float, float, float]) -> np.ndarray:
    """glTF uv (v down the image) of one image as atlas uv (v up), clamped to the image."""
    u0, v0, du, dv = place
    uv = np.clip(np.asarray(uv_down, dtype=np.float64), 0.0, 1.0)
    return np.c_[u0 + uv[:, 0] * du, v0 + (1.0 - uv[:, 1]) * dv].astype(np.float32)


def _resized(image: np.ndarray, scale: float) -> np.ndarray:
    h, w = image.shape[:2]
    size = (max(1, int(w * scale)), max(1, int(h * scale)))
    return np.asarray(Image.fromarray(image[:, :, :3]).resize(size, Image.LANCZOS))
