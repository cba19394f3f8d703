"""Write puppet/data/demo_take.fap: the take the README's main command renders.

A short sentence ("Hello! Nice to meet you.") as visemes with co-articulation (each frame blends
the current viseme into the next one through FAP 1's blend), a smile that grows and a surprised
lift at the end (FAP 2), blinks, glances and a little head motion. 25 frames/s, about 4 s.

    python tools/builders/make_demo_take.py [--out PATH]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from puppet.io.fapfile import FapWriter

FPS = 25
# (viseme, frames): 0 none, 1 p/b/m, 2 f/v, 3 th, 4 t/d, 5 k/g, 6 ch/j/sh, 7 s/z, 8 n/l, 9 r,
# 10 A, 11 e, 12 I, 13 O, 14 U
SENTENCE = [
    (0, 10),
    (5, 2), (11, 4), (8, 3), (13, 6),                      # hello
    (0, 8),
    (8, 3), (10, 4), (12, 2), (7, 3),                      # nice
    (4, 2), (14, 4),                                       # to
    (1, 3), (12, 4), (4, 3),                               # meet
    (14, 7),                                               # you
    (0, 30),
]
BLINKS = (18, 62, 84)
LID_GAP = 1024  # upper to lower lid on the neutral face, in IRISD (the lids touch the iris)
OUT = Path(__file__).resolve().parents[2] / "puppet" / "data" / "demo_take.fap"


def visemes() -> list[tuple[int, int, int]]:
    """Per frame (select1, select2, blend): each viseme blends into the next over its last frames."""
    frames = []
    for i, (viseme, length) in enumerate(SENTENCE):
        following = SENTENCE[i + 1][0] if i + 1 < len(SENTENCE) else 0
        for k in range(length):
            t = max(0.0, (k - length / 2) / (length / 2))
            frames.append((viseme, following, int(round(63 * (1 - 0.5 * t)))))
    return frames


def low_level(frame: int, joy: float) -> np.ndarray:
    """Blinks, glances and head motion for one frame (68 values, index 0 = FAP 1); the head stays
    inside the FAP ranges of fap_coding_params.csv (about 1 degree)."""
    v = np.zeros(68)
    t = frame / FPS
    lower_from_joy = 250 * joy  # at least joy's close_b_*_eyelid (190 in high_level_faps.yaml)
    for start in BLINKS:
        k = frame - start
        if 0 <= k < 5:
            close = np.sin(np.pi * (k + 0.5) / 5)
            v[[20, 21]] = 60 * close
            v[[18, 19]] = (LID_GAP - 40 - lower_from_joy - 60) * close
    glance = 12000 * np.tanh(3 * np.sin(2 * np.pi * t / 3.2))
    v[[22, 23]] = glance
    v[[24, 25]] = -3000 * np.sin(2 * np.pi * t / 2.1)
    v[47] = 1500 * np.sin(2 * np.pi * t / 2.7)
    v[48] = 1800 * np.sin(2 * np.pi * t / 4.0)
    v[49] = 1200 * np.sin(2 * np.pi * t / 3.3)
    return v


def expression(frame: int, n: int) -> tuple[int, int, int, int, int, int]:
    """Joy growing through the sentence, surprise lifting the brows at the end."""
    joy = int(round(63 * min(1.0, frame / (0.6 * n))))
    surprise = int(round(40 * max(0.0, (frame - 0.75 * n) / (0.25 * n))))
    return (1, joy, 6, surprise, 0, 0)


def blink_gap_ok(values: np.ndarray, joy: float) -> bool:
    """The lids never pass each other: upper + lower closing stays under the neutral gap."""
    return values[18] + values[20] + 250 * joy < LID_GAP


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    frames = visemes()
    n = len(frames)
    mask = np.zeros(68, dtype=bool)
    mask[[0, 1, 18, 19, 20, 21, 22, 23, 24, 25, 47, 48, 49]] = True
    with FapWriter(args.out, FPS, "demo_hello") as writer:
        for i, viseme in enumerate(frames):
            feeling = expression(i, n)
            values = low_level(i, feeling[1] / 63)
            assert blink_gap_ok(values, feeling[1] / 63), f"frame {i}: the lids would cross"
            writer.write_frame(values, mask, viseme=(*viseme, 0), expression=feeling)
    print(f"{args.out}: {n} frames at {FPS} frames/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
