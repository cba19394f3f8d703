"""Draw the default face's parted mouths close up beside the artist's same shapes
(``docs/teeth_closeup.png``): open_jaw 400 and the expressions whose lips part (fear, disgust,
surprise), the rig's pose in the top row and the artist's in the bottom one, each labelled with
the share of the opening's middle third that shows upper teeth (``puppet.view.mouthcheck``).
The artist's shapes move the skin only, so their teeth stay at rest (module ``mouthcheck``'s
``artist_shapes``).

    PYTHONPATH=. python tools/figures/teeth_sheet.py [--out PNG]

The artist's shapes are read from ``../shared/assets`` (``$FACEPUPPET_SHARED``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

import puppet
from puppet.bench.assets import shared_assets
from puppet.face.examples import load_examples
from puppet.view.mouthcheck import OPEN_JAW, artist_shapes, posed_mouth_pixels
from puppet.view.renderer import Renderer

POSES = {f"open_jaw {OPEN_JAW:.0f}": {"fap": {"open_jaw": OPEN_JAW}}, "expression 4": {"expression": (4, 63, 0, 0)},
         "expression 5": {"expression": (5, 63, 0, 0)}, "expression 6": {"expression": (6, 63, 0, 0)}}
NAMES = {"expression 4": "fear", "expression 5": "disgust", "expression 6": "surprise"}
WIDTH, HEIGHT, STRIP = 400, 300, 16
SPREAD = 1.6  # the close-up frames the inner lip line this much wider than it is


def close_up(face, vertices: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """The mouth of the posed face, framed on the rest face's inner lip line, front view."""
    lips = face.vertices[face.contours["mouth_opening"]]
    centre = lips.mean(axis=0)
    with Renderer.for_face(face, width=WIDTH, height=HEIGHT, detail=False) as renderer:
        renderer.aim((lips - centre) * SPREAD + centre, view="front")
        return renderer.render(vertices, normals)


def tile(image: np.ndarray, text: str) -> Image.Image:
    out = Image.new("RGB", (WIDTH, HEIGHT + STRIP), "white")
    out.paste(Image.fromarray(image), (0, STRIP))
    ImageDraw.Draw(out).text((4, 2), text, fill="black")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/teeth_closeup.png"))
    args = parser.parse_args()
    face = puppet.load_face()
    runtime = puppet.Runtime(face)
    artist = artist_shapes(face, runtime, load_examples(face, shared_assets() / "makehuman" / "faceunits_arkit"))
    rows: list[list[Image.Image]] = [[], []]
    for name, pose in POSES.items():
        label = NAMES.get(name, name)
        vertices = runtime.deform_faps(**pose)
        normals = runtime.normals(vertices, runtime.fap_controls(**pose)[1])
        shown = posed_mouth_pixels(face, vertices, normals).middle_upper_teeth_fraction
        rows[0].append(tile(close_up(face, vertices, normals), f"{label}: rig, upper teeth in the middle {shown:.0%}"))
        posed = face.vertices + artist[name]
        normals = runtime.normals(posed)
        shown = posed_mouth_pixels(face, posed, normals).middle_upper_teeth_fraction
        rows[1].append(tile(close_up(face, posed, normals), f"{label}: artist, upper teeth in the middle {shown:.0%}"))
    sheet = Image.new("RGB", (WIDTH * len(POSES), 2 * (HEIGHT + STRIP)), "white")
    for r, row in enumerate(rows):
        for c, image in enumerate(row):
            sheet.paste(image, (c * WIDTH, r * (HEIGHT + STRIP)))
    sheet.save(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
