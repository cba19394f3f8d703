"""Detect face landmarks in photos with MediaPipe Face Mesh; print them as JSON on stdout.

Run by ``puppet.photo.detect`` in the photo environment (``.venv-photo``, made by
``tools/setup.sh``), never imported by the project: mediapipe 0.10.21, the last release that
carries its face-landmark model inside the wheel (no download at run time), needs numpy < 2,
which the project's own environment has outgrown. So this file imports nothing of ``puppet``.

    python mediapipe_detect.py PHOTO [PHOTO ...]

prints one line per photo, in order: ``{"faces": N, "size": [W, H], "points": [[x, y, z] * 478]}``:
the 478 refined landmarks (irises included) of the first face, x and y in pixels (y down), z in
MediaPipe's units (about the image width's scale, smaller is nearer the camera); ``points`` is
empty when no face is found. Up to two faces are looked for, so that a photo with several is
told apart from one with one. The model is loaded once for all the photos (a mesh's rendered
views come as one run: ``puppet.view.meshlandmarks``).
"""

from __future__ import annotations

import json
import sys


def detect(mesh, path: str) -> dict:
    """The landmarks of the faces in the photo at ``path``, found by the FaceMesh ``mesh``."""
    import numpy as np
    from PIL import Image

    image = np.asarray(Image.open(path).convert("RGB"))
    height, width = image.shape[:2]
    found = mesh.process(image).multi_face_landmarks or []
    points = [[p.x * width, p.y * height, p.z * width] for p in found[0].landmark] if found else []
    return {"faces": len(found), "size": [width, height], "points": points}


def main(paths: list[str]) -> None:
    import mediapipe as mp

    with mp.solutions.face_mesh.FaceMesh(static_image_mode=True, refine_landmarks=True,
                                         max_num_faces=2, min_detection_confidence=0.5) as mesh:
        for path in paths:
            print(json.dumps(detect(mesh, path)), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
