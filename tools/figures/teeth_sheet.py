"""Draw the default face's parted mouths close up beside the artist's same shapes
(``docs/teeth_closeup.png``): open_jaw 400, the expressions whose lips part (fear, disgust,
surprise) and joy, the rig's pose in the top row and the artist's in the bottom one, each labelled
with the share of the opening's middle third that shows upper teeth (``puppet.view.mouthcheck``)
and how far the lower lip's middle sags below its sides (``puppet.face.lipsag``: a V where it
should stay round).
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
from puppet.face.default import DEFAULT_UNIT_MM
from puppet.face.examples import load_examples
from puppet.face.lipsag import lower_lip_sag
from puppet.view.mouthcheck import OPEN_JAW, artist_shapes, posed_mouth_pixels
from puppet.view.renderer import Renderer

POSES = {f"open_jaw {OPEN_JAW:.0f}": {"fap": {"open_jaw": OPEN_JAW}}} | {
    f"expression {k}": {"expression": (k, 63, 0, 0)} for k in (4, 5, 6, 1)}
NAMES = {"expression 4": "fear", "expression 5": "disgust", "expression 6": "surprise", "expression 1": "joy"}
WIDTH, HEIGHT, STRIP = 400, 300, 16
SPREAD = 1.6  # the close-up frames the inner lip line this much wider than it is


def close_up(face, vertices: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """The mouth of the posed face, framed on the rest face's inner lip line, front view."""
    lips = face.vertices[face.contours["mouth_opening"]]
    centre = lips.mean(axis=0)
    with Renderer.for_face(face, width=WIDTH, height=HEIGHT, detail=False) as renderer:
        renderer.aim((lips - centre) * SPREAD + centre, view="front")
        return renderer.render(vertices, normals)


def figures(face, posed: np.ndarray, normals: np.ndarray) -> str:
    """The label's figures: upper teeth in the middle third, and the lower lip's sag in mm."""
    shown = posed_mouth_pixels(face, posed, normals).middle_upper_teeth_fraction
    sag = lower_lip_sag(face, posed - face.vertices) * DEFAULT_UNIT_MM
    return f"upper teeth in the middle {shown:.0%}, lip sag {sag:+.1f} mm"


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
        rows[0].append(tile(close_up(face, vertices, normals), f"{label}: rig, " + figures(face, vertices, normals)))
        posed = face.vertices + artist[name]
        normals = runtime.normals(posed)
        rows[1].append(tile(close_up(face, posed, normals), f"{label}: artist, " + figures(face, posed, normals)))
    sheet = Image.new("RGB", (WIDTH * len(POSES), 2 * (HEIGHT + STRIP)), "white")
    for r, row in enumerate(rows):
        for c, image in enumerate(row):
            sheet.paste(image, (c * WIDTH, r * (HEIGHT + STRIP)))
    sheet.save(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
