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
shows neither.

An open mouth's lower lip should stay round: ``main`` also prints how far each pose drops the
lower lip's middle below its sides (``puppet.face.lipsag``), in millimetres of the default face.

The teeth a viewer sees first are the upper central incisors, in the middle of the opening; side
teeth toward the corners alone read as a gap-toothed mouth. So the area is also split into its
middle third (by the columns between its leftmost and rightmost pixel) and the sides, and the upper
teeth are told from the lower ones by a third render without the upper teeth: ``MouthPixels``
gives the teeth fraction of each, and of the upper teeth in the middle third. ``mouth_pixels``
poses the face by FAP ``open_jaw`` or by any ``Runtime.deform_faps`` pose (an expression, a
viseme); ``posed_mouth_pixels`` classifies given vertices, such as the face plus an artist's
shape. ``python -m puppet.view.mouthcheck [--artist FOLDER]`` prints the figures for the default face
(beside the artist's, given the artist's ARKit shapes).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from puppet.face.default import DEFAULT_UNIT_MM
from puppet.face.examples import load_examples
from puppet.face.lipsag import lower_lip_sag
from puppet.fap.facs import EXPRESSIONS, artist_shape
from puppet.view.renderer import Renderer

DARK_LUMA = 0.22
"""sRGB luminance (0-1) below which a pixel counts as dark cavity."""

TOOTH_LUMA = 0.35
"""sRGB luminance (0-1) a visible tooth pixel needs to count as a tooth seen (not lost in shadow)."""

TEETH_PARTS = ("teeth_upper", "teeth_lower")

OPEN_JAW = 400.0
"""The open_jaw value (MNS) ``main`` reports: a mouth open for speech, about 7 mm at the lips."""

EXACT = {"samples": 0, "antialias": "none"}
"""Renderer options: one sample per pixel, no post pass (module docstring)."""


@dataclass(frozen=True)
class MouthPixels:
    """Pixel counts inside the projected inner lip line, and the fractions of that area: all of it,
    its middle third (``middle``: the columns of the middle third of its width) and the sides."""

    area: int
    dark: int
    teeth: int
    middle: int = 0
    middle_teeth: int = 0
    middle_upper_teeth: int = 0

    @property
    def dark_fraction(self) -> float:
        return self.dark / self.area if self.area else 0.0

    @property
    def teeth_fraction(self) -> float:
        return self.teeth / self.area if self.area else 0.0

    @property
    def middle_teeth_fraction(self) -> float:
        """Teeth (upper and lower) over the middle third's area."""
        return self.middle_teeth / self.middle if self.middle else 0.0

    @property
    def middle_upper_teeth_fraction(self) -> float:
        """Upper teeth over the middle third's area: the central incisors, seen or not."""
        return self.middle_upper_teeth / self.middle if self.middle else 0.0

    @property
    def side_teeth_fraction(self) -> float:
        """Teeth over the area outside the middle third."""
        sides = self.area - self.middle
        return (self.teeth - self.middle_teeth) / sides if sides else 0.0


def mouth_pixels(face, runtime, open_jaw: float = 400.0, *, pose: dict | None = None, view: str = "front",
                 size: int = 640) -> MouthPixels:
    """Classify the pixels inside the inner lip line of ``face`` posed by ``runtime`` with
    FAP open_jaw = ``open_jaw`` (MNS units), or with ``pose`` (keyword arguments of
    ``Runtime.deform_faps``, such as ``{"expression": (4, 63, 0, 0)}``) when given, rendered at
    ``size`` x ``size`` from ``view`` (framed on the rest face, as ``puppet.view.renderer.render_face``
    does)."""
    pose = {"fap": {"open_jaw": open_jaw}} if pose is None else pose
    vertices = runtime.deform_faps(**pose)
    rigid = runtime.fap_controls(**{k: v for k, v in pose.items() if k in ("fap", "viseme", "expression")})[1]
    return posed_mouth_pixels(face, vertices, runtime.normals(vertices, rigid), view=view, size=size)


def posed_mouth_pixels(face, vertices: np.ndarray, normals: np.ndarray, *, view: str = "front",
                       size: int = 640) -> MouthPixels:
    """``mouth_pixels`` of ``face`` with these posed vertices and normals (module docstring)."""
    with Renderer.for_face(face, width=size, height=size, detail=False, **EXACT) as r:
        r.aim(face.vertices, view=view)
        image = r.render(vertices, normals)
        polygon = r.project(vertices[face.contours["mouth_opening"]])
    bare = _render_without(face, TEETH_PARTS, vertices, normals, view, size)
    no_upper = _render_without(face, ("teeth_upper",), vertices, normals, view, size)
    inside = polygon_mask(polygon, size, size)
    bright = luminance(image) >= TOOTH_LUMA
    is_teeth = inside & _differs(image, bare) & bright
    is_upper = is_teeth & _differs(image, no_upper)
    is_dark = inside & ~is_teeth & (luminance(image) < DARK_LUMA)
    middle = inside & middle_third(inside)
    return MouthPixels(int(inside.sum()), int(is_dark.sum()), int(is_teeth.sum()), int(middle.sum()),
                       int((is_teeth & middle).sum()), int((is_upper & middle).sum()))


def _render_without(face, parts: tuple[str, ...], vertices: np.ndarray, normals: np.ndarray, view: str,
                    size: int) -> np.ndarray:
    """The posed face rendered (``EXACT``) without the triangles all of whose vertices are in ``parts``."""
    drop = np.zeros(len(face.vertices), dtype=bool)
    for part in parts:
        drop[face.parts.get(part, [])] = True
    kept = face.triangles[~drop[face.triangles].all(axis=1)]
    with Renderer(kept, len(face.vertices), face.colors, width=size, height=size, **EXACT) as r:
        r.aim(face.vertices, view=view)
        return r.render(vertices, normals)


def _differs(image: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Pixels where two renders of the same pose differ: a part left out of ``other`` is seen there."""
    return np.abs(image.astype(int) - other.astype(int)).max(axis=2) > 8


def middle_third(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the columns of the middle third of the width ``mask`` spans (all False if empty)."""
    columns = np.flatnonzero(mask.any(axis=0))
    out = np.zeros_like(mask, dtype=bool)
    if len(columns):
        first, width = columns[0], columns[-1] + 1 - columns[0]
        out[:, int(round(first + width / 3)):int(round(first + 2 * width / 3))] = True
    return out


def polygon_mask(points: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) bool mask of the pixels inside a closed polygon of (column, row) points."""
    canvas = Image.new("1", (width, height), 0)
    ImageDraw.Draw(canvas).polygon([tuple(p) for p in np.asarray(points, float)], fill=1)
    return np.asarray(canvas, dtype=bool)


def luminance(image: np.ndarray) -> np.ndarray:
    """Rec. 709 luma of an (H, W, 3) uint8 sRGB image, in 0-1."""
    return (np.asarray(image, float) @ np.array([0.2126, 0.7152, 0.0722])) / 255.0


def main(argv: list[str] | None = None) -> None:
    """Print the mouth figures of the default face at open_jaw 0 and 400 and in the six expressions,
    with ``--artist FOLDER`` each beside the artist's same shape (``artist_shapes``)."""
    import puppet

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--artist", type=Path, help="the artist's ARKit shapes (.target files) of the default face")
    args = parser.parse_args(argv)
    face = puppet.load_face()
    runtime = puppet.Runtime(face)
    poses: dict[str, dict] = {f"open_jaw {v:.0f}": {"fap": {"open_jaw": v}} for v in (0.0, OPEN_JAW)}
    poses |= {f"expression {k}": {"expression": (k, 63, 0, 0)} for k in range(1, 7)}
    artist = artist_shapes(face, runtime, load_examples(face, args.artist)) if args.artist else {}
    rest = runtime.deform_faps()
    for name, pose in poses.items():
        sag = lower_lip_sag(face, runtime.deform_faps(**pose) - rest)
        print(_figures(name, mouth_pixels(face, runtime, pose=pose), sag))
        if name in artist:
            posed = face.vertices + artist[name]
            print(_figures("  artist", posed_mouth_pixels(face, posed, runtime.normals(posed)),
                           lower_lip_sag(face, artist[name])))


def artist_shapes(face, runtime, examples: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The artist's displacements for ``main``'s poses: each expression's FACS sum
    (``puppet.fap.facs``), and for open_jaw ``OPEN_JAW`` the artist's jawOpen at the strength that
    drops the lower lip's middle (2.3) as far. The artist's shapes move the skin only: their teeth
    stay at rest, so the lower teeth show more there than on a face whose jaw turns."""
    out = {f"expression {k}": artist_shape(examples, units) for k, (_, units) in EXPRESSIONS.items()}
    lip = face.feature_vertices["2.3"]
    drop = runtime.deform_faps(fap={"open_jaw": OPEN_JAW})[lip, 1] - face.vertices[lip, 1]
    out[f"open_jaw {OPEN_JAW:.0f}"] = examples["jawOpen"] * drop / examples["jawOpen"][lip, 1]
    return out


def _figures(name: str, m: MouthPixels, sag: float) -> str:
    return (f"{name:14s}: area {m.area:5d} px, dark {m.dark_fraction:6.1%}, teeth {m.teeth_fraction:6.1%} "
            f"(middle third {m.middle_teeth_fraction:6.1%}, upper {m.middle_upper_teeth_fraction:6.1%}; "
            f"sides {m.side_teeth_fraction:6.1%}); lower lip's middle {sag * DEFAULT_UNIT_MM:+5.1f} mm below its sides")


if __name__ == "__main__":
    main()
