"""What a user sees where a face built from a photo stops showing the photo: shared by the photo
tests."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

from puppet.photo.texture import _inside_distance


def outer_band(face) -> np.ndarray:
    """Skin vertices where the photo fades out (weight between 0.05 and 0.95), away from the
    lips and eyes (whose own fades are not the face's edge)."""
    v, w = face.vertices, face.texture_weight
    width = np.ptp(v[face.contours["face_oval"], 0])
    band = np.zeros(len(v), bool)
    band[face.parts["skin"]] = True
    band &= (w > 0.05) & (w < 0.95)
    for contour in ("vermilion_border", "left_lid_opening", "right_lid_opening"):
        band &= _inside_distance(v[face.contours[contour], :2], v[:, :2]) < -0.05 * width
    return band


def seam(face) -> float:
    """The median colour difference (RGB, 0-1) between the photo (a little blurred) and the
    vertex colour over the outer band: what a seam would show."""
    texture = gaussian_filter(face.texture / 255.0, (2, 2, 0))
    h, w = texture.shape[:2]
    band = outer_band(face)
    uv = face.uv[band]
    shown = texture[np.round((1 - uv[:, 1]) * (h - 1)).astype(int), np.round(uv[:, 0] * (w - 1)).astype(int)]
    assert band.sum() > 100, "too few vertices where the photo fades out"
    return float(np.median(np.linalg.norm(shown - face.colors[band], axis=1)))
