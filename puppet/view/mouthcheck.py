"""How much of an open mouth reads as a mouth: dark cavity and teeth inside the inner lip line.

Seen from the front, the area inside the lips' meeting line (the ``mouth_opening`` contour,
feature points 2.2-2.9, deformed and projected) should show mostly a dark cavity with the
teeth in it, not a lit, skin-coloured surface. ``mouth_pixels`` renders the face posed with
an ``open_jaw`` value twice, with and without the teeth, and classifies the pixels of that
area: *teeth* where the teeth are the surface seen (the two renders differ) and bright,
*dark* where the image is dark (low luminance) and no tooth is seen. Both renders are drawn
without antialiasing (``EXACT``): each pixel shows the surface at its centre, so a lip pixel
beside a tooth is not counted as one (FXAA blends neighbours, and on a closed mouth's slit of
one or two pixels it turned lip edges into "teeth"). A closed mouth has an almost empty area and
shows neither. ``python -m puppet.view.mouthcheck`` prints the figures for the default face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw

from puppet.view.renderer import Renderer

DARK_LUMA = 0.22
"""sRGB luminance (0-1) below which a pixel counts as dark cavity."""

TOOTH_LUMA = 0.35
"""sRGB luminance (0-1) a visible tooth pixel needs to count as a tooth seen (not lost in shadow)."""

TEETH_PARTS = ("teeth_upper", "teeth_lower")

EXACT = {"samples": 0, "antialias": "none"}
"""Renderer options: one sample per pixel, no post pass (module docstring)."""


@dataclass(frozen=True)
class MouthPixels:
    """Pixel counts inside the projected inner lip line, and the fractions of that area."""

    area: int
    dark: int
    teeth: int

    @property
    def dark_fraction(self) -> float:
        return self.dark / self.area if self.area else 0.0

    @property
    def teeth_fraction(self) -> float:
        return self.teeth / self.area if self.area else 0.0


def mouth_pixels(face, runtime, open_jaw: float = 400.0, *, view: str = "front",
                 size: int = 640) -> MouthPixels:
    """Classify the pixels inside the inner lip line of ``face`` posed by ``runtime`` with
    FAP open_jaw = ``open_jaw`` (MNS units), rendered at ``size`` x ``size`` from ``view``
    (framed on the rest face, as ``puppet.view.renderer.render_face`` does)."""
    fap = {"open_jaw": open_jaw}
    vertices = runtime.deform_faps(fap)
    normals = runtime.normals(vertices, runtime.fap_controls(fap)[1])
    teeth = np.zeros(len(face.vertices), dtype=bool)
    for part in TEETH_PARTS:
        teeth[face.parts.get(part, [])] = True
    without = face.triangles[~teeth[face.triangles].all(axis=1)]
    with Renderer.for_face(face, width=size, height=size, detail=False, **EXACT) as r:
        r.aim(face.vertices, view=view)
        image = r.render(vertices, normals)
        polygon = r.project(vertices[face.contours["mouth_opening"]])
    with Renderer(without, len(face.vertices), face.colors, width=size, height=size, **EXACT) as r:
        r.aim(face.vertices, view=view)
        bare = r.render(vertices, normals)
    inside = polygon_mask(polygon, size, size)
    luma = luminance(image)
    seen_teeth = np.abs(image.astype(int) - bare.astype(int)).max(axis=2) > 8
    is_teeth = inside & seen_teeth & (luma >= TOOTH_LUMA)
    is_dark = inside & ~(seen_teeth & (luma >= TOOTH_LUMA)) & (luma < DARK_LUMA)
    return MouthPixels(int(inside.sum()), int(is_dark.sum()), int(is_teeth.sum()))


def polygon_mask(points: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) bool mask of the pixels inside a closed polygon of (column, row) points."""
    canvas = Image.new("1", (width, height), 0)
    ImageDraw.Draw(canvas).polygon([tuple(p) for p in np.asarray(points, float)], fill=1)
    return np.asarray(canvas, dtype=bool)


def luminance(image: np.ndarray) -> np.ndarray:
    """Rec. 709 luma of an (H, W, 3) uint8 sRGB image, in 0-1."""
    return (np.asarray(image, float) @ np.array([0.2126, 0.7152, 0.0722])) / 255.0


def main() -> None:
    """Print the mouth figures of the default face at open_jaw 0 and 400."""
    import puppet

    face = puppet.load_face()
    runtime = puppet.Runtime(face)
    for open_jaw in (0.0, 400.0):
        m = mouth_pixels(face, runtime, open_jaw)
        print(f"open_jaw {open_jaw:5.0f}: area {m.area:5d} px, dark {m.dark_fraction:6.1%}, "
              f"teeth {m.teeth_fraction:6.1%}")


if __name__ == "__main__":
    main()
