"""How far a blink closes the default face's eyes: the share of each eye's opening left (the area
between the upper and lower lid margins, seen from the front, over the open eye's) at the poses a
blink takes, as ``Runtime.deform_faps`` shows them (sliver guard included).

    PYTHONPATH=. python tools/checks/eye_closure.py [--tree DIR]

``--tree`` measures another checkout's ``puppet`` (e.g. ``git worktree add /tmp/main main``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

POSES = {
    "upper lids 900 IRISD": {19: 900.0, 20: 900.0},
    "upper lids 1024 (Greta's blinks)": {19: 1024.0, 20: 1024.0},
    "upper 900 + lower 60 (the box's old slider)": {19: 900.0, 20: 900.0, 21: 60.0, 22: 60.0},
    "upper 800 + lower 224 (the artists' split)": {19: 800.0, 20: 800.0, 21: 224.0, 22: 224.0},
}
"""{what: {lid FAP number: value}}: both eyes blink alike."""


def opening(runtime, vertices: np.ndarray, side: str) -> float:
    """The area (front view, x-y) between eye ``side``'s (``l`` or ``r``) upper and lower lid
    margins, traced through the margin control points' vertices across the eye."""
    def margin(lid: str) -> np.ndarray:
        rows = [p.vertex for p in runtime.rig.control_points if p.attach == f"{lid}_lid_{side}"]
        points = np.asarray(vertices, dtype=float)[rows]
        return points[np.argsort(points[:, 0])]

    upper, lower = margin("upper"), margin("lower")
    x = np.linspace(max(upper[0, 0], lower[0, 0]), min(upper[-1, 0], lower[-1, 0]), 400)
    gap = np.interp(x, upper[:, 0], upper[:, 1]) - np.interp(x, lower[:, 0], lower[:, 1])
    return float(np.trapezoid(np.maximum(gap, 0.0), x))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=Path(__file__).resolve().parents[2],
                        help="the checkout whose puppet to measure (default: this one)")
    args = parser.parse_args()
    sys.path.insert(0, str(args.tree.resolve()))
    import puppet

    runtime = puppet.Runtime(puppet.load_face())
    print(f"puppet from {Path(puppet.__file__).parent}: the share of each eye's opening left")
    for name, pose in POSES.items():
        closed = runtime.deform_faps(pose)
        left = [opening(runtime, closed, side) / opening(runtime, runtime.rest, side) for side in "lr"]
        print(f"{name:45s} left eye {100 * left[0]:5.2f}%   right eye {100 * left[1]:5.2f}%")


if __name__ == "__main__":
    main()
