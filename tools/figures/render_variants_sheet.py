"""Before/after/diff sheet of the default face: the old renderer (studio shader, 4x MSAA) and the
new default (untextured variant, this GL's default antialiasing and shading), neutral and joy; writes
docs/render_variants.png and prints the mean absolute differences (0-255)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from test_render_variants import POSES, _images, studio_4x  # noqa: E402

from puppet.face.load import load_face
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import Renderer, save_png


def main(out: str = "docs/render_variants.png", size: tuple[int, int] = (640, 480)) -> None:
    face = load_face()
    runtime = Runtime(face)
    poses = {name: runtime.deform_faps(**kwargs) for name, kwargs in POSES.items()}
    old = _images(studio_4x(face, width=size[0], height=size[1]), face, poses)
    new = _images(Renderer.for_face(face, width=size[0], height=size[1]), face, poses)
    rows = []
    for name in POSES:
        diff = np.abs(old[name].astype(int) - new[name].astype(int))
        print(f"{name}: mean |old - new| = {diff.mean():.3f}/255, max {diff.max()}, "
              f"pixels differing {np.any(diff > 0, axis=2).mean():.1%}")
        amplified = np.clip(diff * 8, 0, 255).astype(np.uint8)
        rows.append(np.concatenate([old[name], new[name], amplified], axis=1))
    save_png(np.concatenate(rows, axis=0), out)
    print(f"{out}: columns old (studio, 4x MSAA) | new default | |diff| x 8; rows {', '.join(POSES)}")


if __name__ == "__main__":
    main()
