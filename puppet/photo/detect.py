"""Landmarks found in a photo offline: MediaPipe Face Mesh in an environment of its own.

mediapipe 0.10.21 carries its face-landmark model inside the wheel, so nothing is downloaded at
run time; it also pins numpy < 2, which this project has outgrown. So it lives in a separate
virtual environment (the ``photo`` set-up: ``tools/setup.sh`` makes ``.venv-photo`` beside
``.venv``) and runs ``puppet/photo/mediapipe_detect.py`` there as a subprocess, which prints the 478
landmarks as JSON. Elsewhere, point ``FACEPUPPET_PHOTO_PYTHON`` at the Python of any environment
with ``mediapipe==0.10.21`` installed.

``detect_landmarks`` refuses, in one line, a photo with no face or with several, and says how to
get the photo environment when there is none.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from puppet.errors import PuppetError

PHOTO_PYTHON = "FACEPUPPET_PHOTO_PYTHON"
DETECTOR = Path(__file__).with_name("mediapipe_detect.py")
TIMEOUT = 120.0


class DetectionError(PuppetError, ValueError):
    """No landmarks could be detected in a photo: which photo, and why."""


def photo_python() -> Path | None:
    """The Python of the photo environment: ``$FACEPUPPET_PHOTO_PYTHON``, else ``.venv-photo``
    beside this environment (the set-up's), else None."""
    given = os.environ.get(PHOTO_PYTHON)
    if given:
        return Path(given)
    beside = Path(sys.prefix).parent / ".venv-photo" / "bin" / "python"
    return beside if beside.exists() else None


def detect_landmarks(photo: str | os.PathLike) -> dict:
    """The photo's 478 MediaPipe landmarks as landmark JSON (``{"layout": "mediapipe468",
    "points": [[x, y, z], ...]}``, pixels), for ``puppet.photo.build.parse_landmarks``."""
    found = detect_faces([photo], str(photo))[0]
    if found["faces"] == 0:
        raise DetectionError(f"{photo}: no face found: expected a frontal photo with the whole face in view")
    if found["faces"] > 1:
        raise DetectionError(f"{photo}: {found['faces']} faces found: crop the photo to the one face to build")
    return {"layout": "mediapipe468", "points": found["points"]}


def detector_python(name: str) -> Path:
    """The photo environment's Python; a ``DetectionError`` naming ``name`` (what the landmarks
    were wanted for) and how to get it when there is none."""
    python = photo_python()
    if python is None or not python.exists():
        raise DetectionError(f"{name}: finding landmarks needs the photo environment (mediapipe 0.10.21): "
                             f"run tools/setup.sh, or set {PHOTO_PYTHON} to a Python that has it; "
                             "or click them: puppet pick-landmarks")
    return python


def detect_faces(photos: list[str | os.PathLike], name: str) -> list[dict]:
    """What the detector finds in each photo, in one run (the model loads once): per photo
    ``{"faces": N, "size": [W, H], "points": [[x, y, z] * 478] or []}`` (``mediapipe_detect``).
    ``name`` is what an error names (the photo, or the mesh the photos are views of)."""
    python = detector_python(name)
    try:
        done = subprocess.run([str(python), str(DETECTOR), *map(str, photos)], capture_output=True, text=True,
                              timeout=TIMEOUT)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise DetectionError(f"{name}: the landmark detector did not run: {exc}") from None
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise DetectionError(f"{name}: the landmark detector failed: {last}")
    return [json.loads(line) for line in done.stdout.splitlines() if line.strip()]
