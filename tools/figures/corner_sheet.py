"""Draw a corner of the face close up, on the default face of another checkout and of this one,
each view's row of the other checkout above this one's, folded triangles marked red
(``puppet.runtime.musclesolver.folded_triangles``):

* ``--corner mouth`` (``docs/mouth_corner.png``): the left mouth corner as the jaw opens (0, 400,
  900 MNS), three-quarter (rows 1-2) and front (rows 3-4);
* ``--corner smile`` (``docs/smile_corner.png``): the same corner in joy at a third, two thirds
  and all of its intensity (the corners raised past the Greta editor's 600 MNS, the fold guard
  holding the slivers inside them), three-quarter (rows 1-2) and front (rows 3-4);
* ``--corner eye`` (``docs/eye_corners.png``): the right eye, both its corners, as its orbicularis
  oculi squints it (0, 0.5, 1) and with every muscle at 0.5, front (rows 1-2) and three-quarter
  (rows 3-4);
* ``--corner blink`` (``docs/blink_corners.png``): the same eye closing (close_t_r_eyelid 700,
  840, 860, 1024 IRISD: where the sliver guard's fallback took over, 850, is between the middle
  two);
* ``--corner close`` (``docs/closed_eye.png``): the same eye closing with the upper lid alone
  (close_t_r_eyelid 900, 1024 IRISD), with the slider box's blink slider at the top (900 and the
  lower lid 60) and as the artists' blink closes it (800 and 224: the lids meet);
* ``--corner frown`` (``docs/frown_blink_corners.png``): the same eye closing under a frown (the
  right brows lowered as far as the face takes them; 700, 1002, 1004, 1024 IRISD: with shapes
  sampled for the lid alone, the outer corner jumped 2.5 mm between the middle two);
* ``--corner cheek`` (``docs/cheek_crease.png``): the skin under the left eye in joy, in the ARKit
  route's smile (mouthSmile and cheekSquint at full, both sides: ``puppet/data/arkit_faps.json``'s
  rows summed) and in cheekSquintLeft alone, three-quarter (rows 1-2) and front (rows 3-4): where
  lift_cheek creased it (``puppet.runtime.creaselimit``).

    PYTHONPATH=. python tools/figures/corner_sheet.py --before DIR [--corner mouth|smile|eye|blink|close|frown|cheek]
        [--out PNG]

``--before`` is a checkout of the project (e.g. ``git worktree add /tmp/before REV``); its tiles
are rendered by running this script there (``--tiles``), with its own face, rig and renderer.
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

SIZE = 320
RED = (230, 20, 20)
EVERY_MUSCLE = "every"  # stands for every muscle of the face at 0.5
FROWN = {"raise_r_i_eyebrow": -220.0, "raise_r_m_eyebrow": -180.0, "raise_r_o_eyebrow": -140.0}
"""The slider box's right brow slider at the bottom of its travel (the face caps it at its reach)."""
LIVE_SMILE = ("mouthSmileLeft", "mouthSmileRight", "cheekSquintLeft", "cheekSquintRight")
"""A phone's full smile on the ARKit route: these blendshapes at 1."""
CORNERS = {
    "mouth": {"out": "mouth_corner.png", "centre": ("8.3",), "shift": (0.0, -0.15, 0.0),
              "views": ((0.6, 0.0, 1.2), (0.0, 0.0, 1.5)),  # camera offsets, dm: three-quarter, front
              "poses": [{"fap": {"open_jaw": opening}} for opening in (0.0, 400.0, 900.0)]},
    "smile": {"out": "smile_corner.png", "centre": ("8.3",), "shift": (0.0, 0.0, 0.0),
              "views": ((0.6, 0.0, 1.2), (0.0, 0.0, 1.5)),
              "poses": [{"expression": (1, intensity, 0, 0)} for intensity in (21, 42, 63)]},
    "eye": {"out": "eye_corners.png", "centre": ("3.8", "3.12"), "shift": (0.0, 0.0, 0.0),
            "views": ((0.0, 0.0, 0.9), (-0.5, 0.0, 0.75)),  # front, three-quarter from the right
            "poses": [{"muscles": {"orbicularis_oculi_r": c}} for c in (0.0, 0.5, 1.0)]
            + [{"muscles": EVERY_MUSCLE}]},
    "blink": {"out": "blink_corners.png", "centre": ("3.8", "3.12"), "shift": (0.0, 0.0, 0.0),
              "views": ((0.0, 0.0, 0.9), (-0.5, 0.0, 0.75)),
              "poses": [{"fap": {"close_t_r_eyelid": value}} for value in (700.0, 840.0, 860.0, 1024.0)]},
    "frown": {"out": "frown_blink_corners.png", "centre": ("3.8", "3.12"), "shift": (0.0, 0.0, 0.0),
              "views": ((0.0, 0.0, 0.9), (-0.5, 0.0, 0.75)),
              "poses": [{"fap": {**FROWN, "close_t_r_eyelid": value}} for value in (700.0, 1002.0, 1004.0, 1024.0)]},
    "close": {"out": "closed_eye.png", "centre": ("3.8", "3.12"), "shift": (0.0, 0.0, 0.0),
              "views": ((0.0, 0.0, 0.9), (-0.5, 0.0, 0.75)),
              "poses": [{"fap": {"close_t_r_eyelid": 900.0}}, {"fap": {"close_t_r_eyelid": 1024.0}},
                        {"fap": {"close_t_r_eyelid": 900.0, "close_b_r_eyelid": 60.0}},
                        {"fap": {"close_t_r_eyelid": 800.0, "close_b_r_eyelid": 224.0}}]},
    "cheek": {"out": "cheek_crease.png", "centre": ("5.3",), "shift": (0.0, 0.1, 0.0),
              "views": ((0.9, 0.1, 1.3), (0.0, 0.0, 1.6)),
              "poses": [{"expression": (1, 63, 0, 0)}, {"arkit": LIVE_SMILE}, {"arkit": ("cheekSquintLeft",)}]},
}
"""Per corner: the sheet's file in docs/, the feature points whose middle (shifted) the camera
looks at, the views and the poses (``Runtime.deform_faps`` arguments, or ``arkit``: ARKit blendshapes at 1)."""


def arkit_pose(names: tuple[str, ...]) -> dict:
    """The ``deform_faps`` arguments of the ARKit blendshapes ``names`` at 1, their rows in this
    checkout's ``puppet/data/arkit_faps.json`` summed."""
    from puppet.live.arkitroute import shipped_vectors

    rows = shipped_vectors()["faps"]
    values: dict[str, float] = {}
    for name in names:
        for fap_name, value in rows[name].items():
            values[fap_name] = values.get(fap_name, 0.0) + value
    return {"fap": values}


def tiles(corner: str) -> list[np.ndarray]:
    """This checkout's renders: for each view, each pose."""
    import puppet
    from puppet.runtime.musclesolver import folded_triangles
    from puppet.view.renderer import Renderer

    face = puppet.load_face()
    runtime = puppet.Runtime(face)
    triangles = np.asarray(face.triangles)
    spec = CORNERS[corner]
    target = np.mean([face.vertices[face.feature_vertices[p]] for p in spec["centre"]], axis=0) + spec["shift"]
    out = []
    with Renderer.for_face(face, width=SIZE, height=SIZE) as renderer:
        for offset in spec["views"]:
            renderer.look_at(target + offset, target, fov=22)
            for pose in spec["poses"]:
                if pose.get("muscles") == EVERY_MUSCLE:
                    pose = {"muscles": dict.fromkeys(runtime.muscle_names, 0.5)}
                if "arkit" in pose:
                    pose = arkit_pose(pose["arkit"])
                vertices = runtime.deform_faps(**pose)
                rigid = runtime.fap_controls(pose.get("fap"))[1]
                image = renderer.render(vertices, runtime.normals(vertices, rigid)).copy()
                folded = np.unique(triangles[folded_triangles(face.vertices, vertices, triangles)])
                for x, y in renderer.project(vertices[folded]):
                    if 0 <= x < SIZE and 0 <= y < SIZE:
                        image[max(int(y) - 2, 0):int(y) + 3, max(int(x) - 2, 0):int(x) + 3] = RED
                out.append(image)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, help="the checkout to draw the row above from")
    parser.add_argument("--corner", choices=sorted(CORNERS), default="mouth")
    parser.add_argument("--out", type=Path, help="default: docs/ and the corner's sheet name")
    parser.add_argument("--tiles", type=Path, help=argparse.SUPPRESS)  # write this checkout's tiles (.npy)
    args = parser.parse_args()
    if not args.tiles and not args.before:
        parser.error("--before is needed")
    if args.tiles:
        np.save(args.tiles, np.stack(tiles(args.corner)))
        return
    with tempfile.TemporaryDirectory() as tmp:
        saved = Path(tmp) / "before.npy"
        env = dict(os.environ, PYTHONPATH=str(args.before.resolve()))
        subprocess.run([sys.executable, str(Path(__file__).resolve()), "--corner", args.corner, "--tiles", str(saved)],
                       cwd=args.before, env=env, check=True)
        before = np.load(saved)
    after = np.stack(tiles(args.corner))
    out = args.out or Path("docs") / CORNERS[args.corner]["out"]
    per_view = len(CORNERS[args.corner]["poses"])
    rows = [np.concatenate(list(images[k:k + per_view]), axis=1)
            for k in range(0, len(after), per_view) for images in (before, after)]
    Image.fromarray(np.concatenate(rows, axis=0)).save(out, optimize=True)
    print(out)


if __name__ == "__main__":
    main()
