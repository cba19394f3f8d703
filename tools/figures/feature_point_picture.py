"""The picture on the guide's feature-point page: the default face from the front with the
feature points ``puppet rig`` needs (``puppet.face.landmarks.FDP_NEEDED``) marked and labelled,
the whole face on the left and the mouth magnified on the right (18 of the points are on the
lips). Writes docs/guide/feature_points.png.

    python tools/figures/feature_point_picture.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from puppet.face.landmarks import FDP_NEEDED  # noqa: E402
from puppet.face.load import load_face  # noqa: E402
from puppet.view.renderer import Renderer  # noqa: E402

OUT = Path(__file__).resolve().parents[2] / "docs" / "guide" / "feature_points.png"
SIZE = 720
MOUTH = [f for f in FDP_NEEDED if f.split(".")[0] in ("2", "8") and f != "2.1"]
# Where each label sits from its point, in pixels of the mouth panel (the lips crowd them).
MOUTH_OFFSETS = {
    "8.4": (-60, 0), "8.3": (16, 0), "2.5": (-50, 22), "2.4": (14, 22),
    "8.1": (-14, -44), "8.9": (-46, -44), "8.10": (14, -44), "8.6": (-58, -18), "8.5": (18, -18),
    "2.2": (-14, -26), "2.7": (-40, -26), "2.6": (12, -26),
    "2.3": (-14, 16), "2.9": (-40, 16), "2.8": (12, 16),
    "8.2": (-14, 30), "8.8": (-50, 22), "8.7": (20, 22),
}
FACE_OFFSETS = {"3.12": (-44, -8), "3.7": (12, -8), "3.8": (-8, 16), "3.11": (-26, 16),
                "3.2": (-14, -30), "3.1": (-14, -30), "3.4": (-14, 10), "3.3": (-14, 10),
                "9.3": (14, -14), "9.15": (14, 0), "2.1": (14, 4)}


def panel(face, points: list[str], around: np.ndarray, offsets: dict, font) -> Image.Image:
    """The face from the front, framed on ``around``, with ``points`` as dots and their ids."""
    with Renderer.for_face(face, width=SIZE, height=SIZE) as r:
        r.aim(around, view="front")
        image = Image.fromarray(r.render(face.vertices))
        where = r.project(np.array([face.feature_points[f] for f in points]))
    draw = ImageDraw.Draw(image)
    for fdp, (x, y) in zip(points, where):
        draw.ellipse([x - 5, y - 5, x + 5, y + 5], fill=(255, 220, 0), outline=(0, 0, 0), width=2)
        dx, dy = offsets.get(fdp, (10, -10))
        draw.line([x, y, x + dx + (0 if dx > 0 else 30), y + dy + 8], fill=(0, 0, 0), width=1)
        box = draw.textbbox((x + dx, y + dy), fdp, font=font)
        draw.rectangle([box[0] - 2, box[1] - 1, box[2] + 2, box[3] + 1], fill=(255, 255, 255))
        draw.text((x + dx, y + dy), fdp, fill=(0, 0, 0), font=font)
    return image


def square_around(face, points: list[str], half: float) -> np.ndarray:
    """Corners of a box centred on ``points``, ``half`` their width from the centre across, as deep as
    the face (the camera's clip planes come from the box aimed at)."""
    at = np.array([face.feature_points[f] for f in points])
    centre, reach = at.mean(axis=0), half * np.ptp(at[:, 0])
    depth = face.vertices[face.parts["skin"], 2]
    return np.array([(centre[0] + sx * reach, centre[1] + sy * reach, z)
                     for sx in (-1, 1) for sy in (-1, 1) for z in (depth.min(), depth.max())])


def main() -> None:
    face = load_face()
    font = ImageFont.load_default(size=18)
    whole = panel(face, [f for f in FDP_NEEDED if f not in MOUTH], square_around(face, FDP_NEEDED, 0.75),
                  FACE_OFFSETS, font)
    mouth = panel(face, MOUTH, square_around(face, MOUTH, 0.62), MOUTH_OFFSETS, font)
    sheet = Image.new("RGB", (2 * SIZE, SIZE), (255, 255, 255))
    sheet.paste(whole, (0, 0))
    sheet.paste(mouth, (SIZE, 0))
    sheet.save(OUT, optimize=True)
    print(f"{OUT}: {len(FDP_NEEDED)} feature points")


if __name__ == "__main__":
    main()
