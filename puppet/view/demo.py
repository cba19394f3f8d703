"""The main job on the embedded default face: replay the shipped demo take to a video, with its voice.

``demo_take.fap`` (made by ``tools/builders/make_demo_take.py``) says a short sentence in visemes with a
growing smile, blinks, glances and head motion; ``demo_speech.wav`` (``tools/builders/make_demo_speech.py``)
is that sentence spoken. The demo lays the mouth the voice makes over the take, as ``puppet
lipsync --over`` does (the take folder ``demo_take/`` beside the video), renders it to MP4 with
the sound, and also writes a still of the frame with the mouth open widest beside the neutral
face, for a quick look without a player.
"""

from __future__ import annotations

import importlib.resources
import shutil
from pathlib import Path

import numpy as np

from puppet.io.fapfile import iter_fap
from puppet.io.soundtrack import soundtrack
from puppet.live.lipsync import lipsync
from puppet.view.muxsound import write_video_with_sound
from puppet.view.renderer import Renderer, save_png
from puppet.view.rendertake import FapPlayback, aim_at_head


def demo_take() -> Path:
    """Path of the demo take shipped in the package."""
    return Path(str(importlib.resources.files("puppet").joinpath("data", "demo_take.fap")))


def demo_speech() -> Path:
    """Path of the demo's spoken sentence shipped in the package."""
    return Path(str(importlib.resources.files("puppet").joinpath("data", "demo_speech.wav")))


def run_demo(out: Path, size: tuple[int, int] = (640, 480), view: str = "three_quarter") -> list[Path]:
    """Render the demo take with its voice to ``out/demo_take.mp4`` (the take in ``out/demo_take/``)
    and ``out/demo_still.png``; return the paths."""
    out.mkdir(parents=True, exist_ok=True)
    take = out / "demo_take"
    if take.exists():
        shutil.rmtree(take)
    with iter_fap(demo_take()) as reader:
        fps = round(reader.header.fps)
    lipsync(demo_speech(), take, over=demo_take(), fps=fps)
    playback = FapPlayback(take)
    face = playback.face
    neutral = face.vertices
    video = out / "demo_take.mp4"
    with Renderer.for_face(face, width=size[0], height=size[1]) as renderer:
        aim_at_head(renderer, face, view)
        still = _Still(face.feature_vertices["2.2"], face.feature_vertices["2.3"])
        frames = (still.keep(renderer.render(v, n), v) for v, n in playback)
        write_video_with_sound(frames, video, playback.fps, soundtrack(take))
        rest = renderer.render(neutral.astype(np.float32))
    picture = out / "demo_still.png"
    save_png(np.hstack([rest, still.image]), picture)
    return [video, picture]


class _Still:
    """Keeps the rendered frame with the widest vertical gap between the inner lips (2.2, 2.3)."""

    def __init__(self, upper_lip: int, lower_lip: int) -> None:
        self.lips = (upper_lip, lower_lip)
        self.best = -1.0
        self.image: np.ndarray | None = None

    def keep(self, image: np.ndarray, vertices: np.ndarray) -> np.ndarray:
        gap = float(vertices[self.lips[0], 1] - vertices[self.lips[1], 1])
        if gap > self.best:
            self.best, self.image = gap, image
        return image
