"""Measure the FAP encoder against the decoder: encode(decode(x)) - x on random frames.

For each of N random frames of every FAP the default face can show (translations within
+-300 FAPU, rotations within the clamp ranges), decode with the runtime (float32, as played, and
float64), measure the mesh back into FAPs, and print the median and worst error per kind.

    python tools/checks/fap_roundtrip.py [frames]
"""

from __future__ import annotations

import sys

import numpy as np

from puppet.face.load import load_face
from puppet.fap.table import faps
from puppet.runtime.runtime import Runtime


def random_frame(rng: np.random.Generator, effects: dict[int, str]) -> np.ndarray:
    x = np.zeros(68)
    for f in faps():
        if f.number > 2 and not effects[f.number].startswith("nothing") and f.number != 46:
            x[f.number - 1] = rng.uniform(-300, 300) if f.bidirectional else rng.uniform(0, 300)
    x[[47, 48, 49]] = rng.uniform(-1800, 1800, 3)
    return x


def main(frames: int = 50) -> None:
    face = load_face()
    rng = np.random.default_rng(11)
    for dtype in (np.float32, np.float64):
        runtime = Runtime(face, dtype=dtype)
        effects = runtime.faps.effects()
        moving = np.array([effects[n].startswith("moves control point") for n in range(1, 69)])
        errors = []
        for _ in range(frames):
            x = random_frame(rng, effects)
            errors.append(runtime.faps.encode(runtime.deform_faps(x)) - x)
        errors = np.abs(np.array(errors))
        translations, others = errors[:, moving], errors[:, ~moving]
        print(f"{np.dtype(dtype).name}: translational FAPs |error| median {np.median(translations):.2e}, "
              f"max {translations.max():.2e} FAPU; rigid ones max {others.max():.2e}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 50)
