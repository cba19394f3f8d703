"""Measure the lips in video frames with MediaPipe Face Mesh; print one JSON line per frame.

Run by ``puppet.bench.voicetruth`` in the photo environment (``.venv-photo``; see
``puppet.photo.detect`` for why it is apart), never imported by the project.

    python mediapipe_lips.py WIDTH HEIGHT < frames.rgb

reads raw RGB frames of WIDTH x HEIGHT from standard input (as ``ffmpeg -f rawvideo -pix_fmt
rgb24`` writes them) and prints, per frame, ``{"found": bool, "opening": px, "mouth_width": px,
"face_width": px}``: the inner lips' midpoints apart (landmarks 13 and 14), the inner mouth
corners (78, 308) and the face's sides (234, 454), tracked from frame to frame.
"""

from __future__ import annotations

import json
import math
import sys

PAIRS = {"opening": (13, 14), "mouth_width": (78, 308), "face_width": (234, 454)}


def main(width: int, height: int) -> None:
    import mediapipe as mp
    import numpy as np

    size = width * height * 3
    with mp.solutions.face_mesh.FaceMesh(static_image_mode=False, refine_landmarks=True, max_num_faces=1,
                                         min_detection_confidence=0.5, min_tracking_confidence=0.5) as mesh:
        while len(data := sys.stdin.buffer.read(size)) == size:
            found = mesh.process(np.frombuffer(data, np.uint8).reshape(height, width, 3)).multi_face_landmarks
            row: dict = {"found": bool(found)}
            if found:
                points = found[0].landmark
                for name, (a, b) in PAIRS.items():
                    row[name] = math.hypot((points[a].x - points[b].x) * width, (points[a].y - points[b].y) * height)
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]))
