"""Draw docs/mouth_corner.png: the left mouth corner close up as the jaw opens (0, 400, 900 MNS), on
the default face of another checkout and of this one: three-quarter (rows 1-2), front (rows 3-4),
each time the other checkout's row above this one's.

    PYTHONPATH=. .venv/bin/python tools/mouth_corner_sheet.py --before DIR [--out docs/mouth_corner.png]

``--before`` is a checkout of the project (e.g. ``git worktree add /tmp/before REV``); its tiles
are rendered by running this script there (``--tiles``), with its own face, rig and renderer.
Folded triangles (``puppet.runtime.musclesolver.folded_triangles``) are marked red.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

OPENINGS = (0.0, 400.0, 900.0)  # open_jaw, MNS
VIEWS = {"three-quarter": (0.6, 0.0, 1.2), "front": (0.0, 0.0, 1.5)}  # camera offsets, dm
SIZE = 320
RED = (230, 20, 20)


def tiles() -> list[np.ndarray]:
    """This checkout's renders: for each view, each opening."""
    import puppet
    from puppet.runtime.musclesolver import folded_triangles
    from puppet.view.renderer import Renderer

    face = puppet.load_face()
    runtime = puppet.Runtime(face)
    triangles = np.asarray(face.triangles)
    target = face.vertices[face.feature_vertices["8.3"]] - (0.0, 0.15, 0.0)
    out = []
    with Renderer.for_face(face, width=SIZE, height=SIZE) as renderer:
        for offset in VIEWS.values():
            renderer.look_at(target + offset, target, fov=22)
            for opening in OPENINGS:
                pose = {"fap": {"open_jaw": opening}}
                vertices = runtime.deform_faps(**pose)
                image = renderer.render(vertices, runtime.normals(vertices, runtime.fap_controls(**pose)[1])).copy()
                folded = np.unique(triangles[folded_triangles(face.vertices, vertices, triangles)])
                for x, y in renderer.project(vertices[folded]):
                    if 0 <= x < SIZE and 0 <= y < SIZE:
                        image[max(int(y) - 2, 0):int(y) + 3, max(int(x) - 2, 0):int(x) + 3] = RED
                out.append(image)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, help="the checkout to draw the row above from")
    parser.add_argument("--out", type=Path, default=Path("docs") / "mouth_corner.png")
    parser.add_argument("--tiles", type=Path, help=argparse.SUPPRESS)  # write this checkout's tiles (.npy)
    args = parser.parse_args()
    if not args.tiles and not args.before:
        parser.error("--before is needed")
    if args.tiles:
        np.save(args.tiles, np.stack(tiles()))
        return
    with tempfile.TemporaryDirectory() as tmp:
        saved = Path(tmp) / "before.npy"
        env = dict(os.environ, PYTHONPATH=str(args.before.resolve()))
        subprocess.run([sys.executable, str(Path(__file__).resolve()), "--tiles", str(saved)],
                       cwd=args.before, env=env, check=True)
        before = np.load(saved)
    after = np.stack(tiles())
    per_view = len(OPENINGS)
    rows = [np.concatenate(list(images[k:k + per_view]), axis=1)
            for k in range(0, len(after), per_view) for images in (before, after)]
    Image.fromarray(np.concatenate(rows, axis=0)).save(args.out, optimize=True)
    print(args.out)


if __name__ == "__main__":
    main()
