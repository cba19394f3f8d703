"""Every triangle against levels of detail: the default face at the live window's 640x480, neutral
and with the mouth wide open, from the front and three-quarter; columns every triangle drawn |
eyeballs and teeth from their coarse levels (the default) | |difference| x 8, the eyes and mouth
magnified twice. Writes docs/part_detail.png and prints the mean absolute differences (0-255)
and the triangles drawn.

    python tools/figures/part_detail_sheet.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from test_partdetail import OPEN_MOUTH  # noqa: E402

from puppet.face.load import load_face
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import Renderer, save_png
from puppet.view.rendertake import aim_at_head

ROWS = (("front", "neutral"), ("front", "open mouth"), ("three_quarter", "open mouth"))


def main(out: str = "docs/part_detail.png", size: tuple[int, int] = (640, 480)) -> None:
    face = load_face()
    runtime = Runtime(face)
    poses = {"neutral": runtime.rest, "open mouth": runtime.deform_faps(OPEN_MOUTH)}
    rows = []
    for view, pose in ROWS:
        vertices = poses[pose]
        images = []
        for detail in (False, True):
            with Renderer.for_face(face, width=size[0], height=size[1], detail=detail) as renderer:
                aim_at_head(renderer, face, view)
                images.append(renderer.render(vertices, runtime.normals(vertices)))
                drawn = len(renderer.detail.triangles(renderer.levels)) if detail else len(face.triangles)
                inner = np.concatenate([face.parts[p] for p in ("eye_l", "eye_r", "teeth_upper", "teeth_lower")])
                centre = renderer.project(vertices[inner]).mean(axis=0)
        diff = np.abs(images[0].astype(int) - images[1].astype(int))
        print(f"{view}, {pose}: mean |every - levels| = {diff.mean():.3f}/255, max {diff.max()}, "
              f"pixels differing {np.any(diff > 0, axis=2).mean():.2%}; {drawn} of {len(face.triangles)} triangles drawn")
        amplified = np.clip(diff * 8, 0, 255).astype(np.uint8)
        rows.append(np.concatenate([_zoom(image, centre) for image in (*images, amplified)], axis=1))
    save_png(np.concatenate(rows, axis=0), out)
    print(f"{out}: columns every triangle | levels of detail | |diff| x 8; rows "
          f"{', '.join(f'{view} {pose}' for view, pose in ROWS)}")


def _zoom(image: np.ndarray, centre: np.ndarray, half: int = 110) -> np.ndarray:
    """The square of ``image`` around ``centre`` (column, row) holding the eyes and mouth, twice as large."""
    column, row = np.clip(np.round(centre).astype(int), half, np.array(image.shape[1::-1]) - half)
    return image[row - half:row + half, column - half:column + half].repeat(2, axis=0).repeat(2, axis=1)


if __name__ == "__main__":
    main()
