"""Where the ICT head rigged by transfer creases, without and with its skin smoothing.

    PYTHONPATH=. .venv/bin/python tools/figures/crease_sheet.py [--out docs/crease_sheet.png] [--size 360]

The ICT mesh is rigged as a user rigs it (``puppet rig`` from its 68 landmarks, as
``tools/figures/rig_faces.py`` does). The sheet's top row is that rig with its ``smoothed`` vertices left
out (``puppet.runtime.skinsmoothing``), the bottom row the rig as written. Columns: joy, sadness,
surprise and fear (FAP 2 at intensity 63) and viseme 10. Each edge that bends further than the
default face bends at the same place in the same pose (``puppet.runtime.posecheck.PoseCheck``)
reddens its vertices, full red at 15 degrees beyond; the creased edges per pose are printed.
Needs the ICT asset under ``../shared/assets`` (``$FACEPUPPET_SHARED``).
"""

from __future__ import annotations

import argparse
import copy
import sys
import tempfile
from pathlib import Path

import numpy as np

from puppet.bench.assets import shared_assets
from puppet.face.default import default_face, load_default_rig
from puppet.runtime.posecheck import POSES, PoseCheck
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import SKIN_SRGB, Renderer, save_png
from tools.figures.rig_faces import drawn_triangles, ict_inputs, rigged_by_cli

SHOWN = ("joy", "sadness", "surprise", "fear", "viseme 10")
FULL_RED = np.radians(15.0)


def crease_colors(check: PoseCheck, name: str, posed: np.ndarray) -> np.ndarray:
    """Skin colour reddened at each vertex by how far its edges bend beyond their bound."""
    over = check.excess(name, posed)
    heat = np.zeros(len(check.rest))
    for k in range(2):
        np.maximum.at(heat, check.hinges.edges[:, k], over)
    share = np.clip(heat / FULL_RED, 0.0, 1.0)[:, None]
    return (np.asarray(SKIN_SRGB, float) * (1 - share) + np.array([1.0, 0.0, 0.0]) * share).astype(np.float32)


def row(face, runtime: Runtime, check: PoseCheck, size: int, label: str) -> np.ndarray:
    """The ``SHOWN`` poses of ``runtime`` side by side, creases in red; counts printed."""
    front = np.concatenate([r.vertices for r in runtime.rig.regions if r.kind == "dffd"])
    tiles, counts = [], []
    for name in SHOWN:
        posed = runtime.deform_faps(**POSES[name])
        counts.append(f"{name} {int(check.creased(name, posed).sum())}")
        with Renderer(drawn_triangles(face), len(face.vertices), crease_colors(check, name, posed),
                      width=size, height=size) as renderer:
            renderer.aim(face.vertices[front])
            tiles.append(renderer.render(np.asarray(posed, dtype=np.float32)))
    print(f"{label}: creased edges {', '.join(counts)}")
    return np.hstack(tiles)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/crease_sheet.png")
    parser.add_argument("--size", type=int, default=360, help="tile size in pixels")
    args = parser.parse_args()
    given = ict_inputs(shared_assets())
    if given is None:
        sys.exit(f"the ICT asset is not under {shared_assets()}")
    with tempfile.TemporaryDirectory() as scratch:
        (Path(scratch) / "ict").mkdir()
        face = rigged_by_cli(*given, Path(scratch) / "ict")
        smoothed = Runtime(face, cache=False)
    rig = copy.copy(smoothed.rig)
    rig.smoothed = np.zeros(0, dtype=np.int64)
    check = PoseCheck(face, Runtime(default_face(), load_default_rig()))
    sheet = np.vstack([row(face, Runtime(face, rig, cache=False), check, args.size, "without its smoothing"),
                       row(face, smoothed, check, args.size, f"as rigged ({len(smoothed.rig.smoothed)} smoothed)")])
    save_png(sheet, args.out)
    print(f"crease sheet: {args.out} (rows without / with smoothing; columns {', '.join(SHOWN)})")


if __name__ == "__main__":
    main()
