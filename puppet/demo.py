"""The main job on the embedded default face: render it neutral and deformed.

The deformed pose drives the rig directly (issue 3 puts MPEG-4 FAPs in front of it): the jaw
opens, the lip corners rise and widen into a smile, the brows lift, the head turns a little and
the eyes look aside, so every kind of motion the rig has is visible in one picture.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import rigid
from .face import load_face
from .render import Renderer, save_png
from .runtime import Runtime


def demo_pose(runtime: Runtime) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Displacements (K, 3) and rigid motions of the demo expression, in the face's own scale."""
    face, rig = runtime.face, runtime.rig
    unit = abs(face.feature_points["3.5"][0] - face.feature_points["3.6"][0])
    moves = {
        "8.3": (0.06, 0.05, -0.01), "8.4": (-0.06, 0.05, -0.01),
        "2.4": (0.06, 0.05, -0.01), "2.5": (-0.06, 0.05, -0.01),
        "8.1": (0.0, 0.02, 0.01), "2.2": (0.0, 0.03, 0.0),
        "4.1": (0.0, 0.05, 0.0), "4.2": (0.0, 0.05, 0.0),
        "4.3": (0.0, 0.07, 0.01), "4.4": (0.0, 0.07, 0.01),
        "4.5": (0.0, 0.04, 0.0), "4.6": (0.0, 0.04, 0.0),
        "5.3": (0.01, 0.03, 0.01), "5.4": (-0.01, 0.03, 0.01),
    }
    d = np.zeros((len(runtime.control_points), 3))
    for i, name in enumerate(runtime.control_points):
        if name in moves:
            d[i] = np.array(moves[name]) * unit
    jaw = rig.rigid_parts["jaw"]
    eyes = rigid.rotation((0, 1, 0), np.radians(12))
    motions = {
        "jaw": rigid.about(jaw.pivot, rigid.rotation(jaw.axis, np.radians(11))),
        "eye_l": rigid.about(rig.rigid_parts["eye_l"].pivot, eyes),
        "eye_r": rigid.about(rig.rigid_parts["eye_r"].pivot, eyes),
        "head": rigid.about(rig.rigid_parts["head"].pivot,
                            rigid.rotation((0, 1, 0), np.radians(-8)) @ rigid.rotation((1, 0, 0), np.radians(4))),
    }
    return d, motions


def run_demo(out: Path, size: int = 720) -> list[Path]:
    """Render neutral.png, deformed.png and side_by_side.png into ``out``; return their paths."""
    out.mkdir(parents=True, exist_ok=True)
    face = load_face()
    runtime = Runtime(face)
    d, motions = demo_pose(runtime)
    with Renderer(face.triangles, len(face.vertices), face.colors, width=size, height=size) as renderer:
        head = face.vertices[face.parts["skin"]]
        renderer.frame(head[head[:, 1] > runtime.rig.rigid_parts["head"].neck[0]], view="three_quarter")
        neutral = renderer.render(*runtime.deform_with_normals(np.zeros_like(d)))
        deformed = renderer.render(*runtime.deform_with_normals(d, motions))
    paths = [out / "neutral.png", out / "deformed.png", out / "side_by_side.png"]
    for image, path in zip((neutral, deformed, np.hstack([neutral, deformed])), paths):
        save_png(image, path)
    return paths
