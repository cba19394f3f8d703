"""Contact sheet of a face built from one photo: the photo (cut to the head), then the built face
from the front, three-quarter and profile, neutral (top row) and smiling (bottom row: FAP 2 joy
with the jaw a little open, which shows the face's own teeth), as ``puppet face-from-photo``
makes it with no ``--landmarks`` (MediaPipe, the photo set-up).

Run: PYTHONPATH=. .venv/bin/python tools/figures/photo_sheet.py [PHOTO] [-o docs/photo_face_sheet.png]
(default photo: scikit-image's astronaut, public domain, NASA).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

from puppet.face.folder import load_face_folder, load_folder_rig
from puppet.photo.build import build_face_folder
from puppet.photo.detect import detect_landmarks
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import Renderer, save_png

ROOT = Path(__file__).resolve().parents[2]
VIEWS = ("front", "three_quarter", "profile")
POSES = {"neutral": {}, "smiling": {"fap": {"open_jaw": 120}, "expression": (1, 63, 0, 0)}}
TILE = 400


def sheet(photo: Path, work: Path) -> np.ndarray:
    """The contact sheet (rows: poses; columns: the photo, then the views)."""
    landmarks = detect_landmarks(photo)
    (work / "landmarks.json").write_text(json.dumps(landmarks), encoding="utf-8")
    folder = build_face_folder(photo, work / "landmarks.json", work / "face")
    face = load_face_folder(folder)
    runtime = Runtime(face, load_folder_rig(folder))
    points = np.array(landmarks["points"])[:, :2]
    centre, half = points.mean(axis=0), 0.8 * np.ptp(points, axis=0).max()
    picture = Image.open(photo).convert("RGB").crop((*(centre - half).astype(int), *(centre + half).astype(int)))
    tile = np.asarray(picture.resize((TILE, TILE), Image.LANCZOS))
    rows = []
    with Renderer.for_face(face, width=TILE, height=TILE) as renderer:
        for k, pose in enumerate(POSES.values()):
            vertices = runtime.deform_faps(**pose)
            cells = [tile if k == 0 else np.full_like(tile, 255)]
            for view in VIEWS:
                renderer.aim(face.vertices, view=view)
                cells.append(renderer.render(vertices))
            rows.append(np.concatenate(cells, axis=1))
    return np.concatenate(rows, axis=0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("photo", nargs="?", help="the photo (default: scikit-image's astronaut)")
    parser.add_argument("-o", "--output", default=str(ROOT / "docs" / "photo_face_sheet.png"))
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as work:
        photo = Path(args.photo) if args.photo else Path(work) / "astronaut.png"
        if not args.photo:
            from skimage import data

            Image.fromarray(data.astronaut()).save(photo)
        save_png(sheet(photo, Path(work)), args.output)
    print(f"{args.output}: {photo.name}; columns photo, {', '.join(VIEWS)}; rows {', '.join(POSES)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
