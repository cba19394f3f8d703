"""Draw docs/folds.png: the poses that folded the default face worst, before and after its fold
limits (puppet.runtime.foldlimits), front view, framed on the face as tools/checks/realism.py frames it.

    .venv/bin/python tools/figures/fold_sheet.py [--before RIG] [--out docs/folds.png]

``--before`` is the rig to compare with (default: the shipped rig as git's ``HEAD~N`` has it is not
assumed; pass a saved rig file, e.g. ``git show REV:puppet/data/default_rig.json > /tmp/old.rig``).
Each pair of tiles: the pose on the old rig (folded triangles painted red, their count in the
label), then on the shipped rig.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import puppet
from puppet.face.rig import load_rig
from puppet.runtime.musclesolver import folded_triangles
from puppet.view.renderer import Renderer

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: tools.* as packages
from tools.checks.realism import TILE, frame, labelled, sheet  # noqa: E402

POSES = [("raise_l_o_eyebrow -900", {"fap": {35: -900}}), ("raise_l_m_eyebrow -900", {"fap": {33: -900}}),
         ("shift_jaw 1080", {"fap": {15: 1080}}), ("stretch_l_cornerlip_o -600", {"fap": {53: -600}}),
         ("stretch_l_cornerlip 600", {"fap": {6: 600}}), ("close_t_l_eyelid -1080", {"fap": {19: -1080}}),
         ("close_t_l_eyelid 1080", {"fap": {19: 1080}}), ("open_jaw 1080", {"fap": {3: 1080}}),
         ("joy", {"expression": (1, 63, 0, 0)}), ("sadness", {"expression": (2, 63, 0, 0)}),
         ("anger", {"expression": (3, 63, 0, 0)}), ("fear", {"expression": (4, 63, 0, 0)}),
         ("surprise", {"expression": (6, 63, 0, 0)}), ("viseme 10", {"viseme": (10, 0, 63)}),
         ("viseme 13", {"viseme": (13, 0, 63)}), ("viseme 14", {"viseme": (14, 0, 63)})]
RED = np.array([230, 20, 20], dtype=np.uint8)


def render(renderer: Renderer, face, runtime, pose: dict) -> tuple[np.ndarray, int]:
    """The pose rendered, folded triangles' vertices painted red, and how many folded."""
    vertices = runtime.deform_faps(**pose)
    normals = runtime.normals(vertices, runtime.fap_controls(**pose)[1])
    triangles = np.asarray(face.triangles)
    folded = folded_triangles(face.vertices, vertices, triangles)
    image = renderer.render(vertices, normals)
    if folded.any():
        image = image.copy()
        points = np.unique(triangles[folded])
        for x, y in renderer.project(vertices[points]):
            xi, yi = int(round(x)), int(round(y))
            image[max(yi - 1, 0):yi + 2, max(xi - 1, 0):xi + 2] = RED
    return image, int(folded.sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, required=True, help="the rig file to compare with")
    parser.add_argument("--out", type=Path, default=Path("docs") / "folds.png")
    args = parser.parse_args()
    face = puppet.load_face()
    before, after = puppet.Runtime(face, load_rig(args.before)), puppet.Runtime(face)
    tiles = []
    with Renderer.for_face(face, width=TILE + 60, height=TILE + 60) as renderer:
        frame(renderer, face, "front")
        for label, pose in POSES:
            for name, runtime in (("before", before), ("after", after)):
                image, count = render(renderer, face, runtime, pose)
                tiles.append(labelled(image, f"{label}: {name}, {count} folds"))
    sheet(tiles, 8).save(args.out, optimize=True)
    print(args.out)


if __name__ == "__main__":
    main()
