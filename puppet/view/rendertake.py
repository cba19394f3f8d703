"""Playing a FAP take on a face: frames to poses, offscreen to video, or in a window.

A .fap frame transmits only its masked FAPs; the others keep the value they last had (the
decoder's rule in MPEG-4 players), starting from neutral. ``FapPlayback`` applies that rule while
streaming, so a take of any length plays in constant memory, and hands each frame's vertices
and normals to whatever draws them.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator

import numpy as np

from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.fap.held import held_low_level
from puppet.fap.pose import Pose
from puppet.io.fapfile import iter_fap
from puppet.io.outputs import writable
from puppet.io.soundtrack import soundtrack
from puppet.io.takes import TakeError, take_fap
from puppet.runtime.runtime import Runtime
from puppet.view.muxsound import write_video_with_sound
from puppet.view.renderer import VIEW_DIRECTIONS, Renderer

VIEWS = tuple(VIEW_DIRECTIONS)


class FapPlayback:
    """Streams a .fap take (the file, or a take folder) as (vertices, normals) per frame on a face;
    with ``normals`` off, (vertices, None): for a renderer whose draw sums them (``gpu_normals``)."""

    def __init__(self, path: str | os.PathLike, face: Face | None = None,
                 runtime: Runtime | None = None) -> None:
        self.path = take_fap(path)
        with iter_fap(self.path) as reader:
            self.header = reader.header
        self.face = face if face is not None else load_face()
        self.runtime = runtime if runtime is not None else Runtime(self.face)
        self.normals = True

    @property
    def fps(self) -> float:
        return self.header.fps

    def __iter__(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        with iter_fap(self.path) as reader:
            for values in held_low_level(reader):
                yield self.runtime.deform_pose(Pose(values), normals=self.normals)


def render_take(path: str | os.PathLike, out: str | os.PathLike, *, face: Face | None = None,
                size: tuple[int, int] = (640, 480), view: str = "front", fps: float | None = None,
                progress: bool = True, runtime: Runtime | None = None, antialias: str | None = None) -> int:
    """Render a .fap take to an MP4 at the take's fps (or ``fps``); return the frame count.
    ``runtime`` (of ``face``) saves building one when many takes are rendered in turn;
    ``antialias`` None draws as the live window does on this GL (``renderer.choose_antialias``).
    A take folder with sound gets it as the video's AAC track, its first sample on frame 0
    (``puppet.io.soundtrack``; a damaged WAV renders silent, with a warning naming it).

    The video is written beside ``out`` and renamed into place only when every frame has been
    rendered, so a bad take never leaves a broken video behind. The take, its folder and ``out``
    are checked before the first frame (an ``OutputError`` for a path that cannot be written).
    """
    out = writable(out, "video")
    playback = FapPlayback(path, face, runtime)
    sound = soundtrack(path)
    rate = playback.fps if fps is None else fps
    if sound and rate != playback.fps:
        warnings.warn(f"{path}: drawn at {rate:g} frames/s, not the take's {playback.fps:g}: its sound "
                      "keeps its own pace and drifts from the face", stacklevel=2)
    partial = out.with_name(f".{out.stem}.partial{out.suffix}")
    try:
        with Renderer.for_face(playback.face, width=size[0], height=size[1], antialias=antialias) as renderer:
            aim_at_head(renderer, playback.face, view)
            playback.normals = not renderer.gpu_normals
            total = playback.header.declared_frames
            frames = _progress((renderer.render(v, n) for v, n in playback), total, progress)
            count = write_video_with_sound(_not_empty(frames, path), partial, rate, sound)
        partial.replace(out)
        return count
    finally:
        partial.unlink(missing_ok=True)


def _not_empty(frames: Iterator[np.ndarray], path: str | os.PathLike) -> Iterator[np.ndarray]:
    """The frames; a TakeError if there are none."""
    first = next(frames, None)
    if first is None:
        raise TakeError(f"{path}: the take holds no frames")
    yield first
    yield from frames



def aim_at_head(renderer: Renderer, face: Face, view: str) -> None:
    """Aim the camera at the head (above the neck), from a named view."""
    if view not in VIEWS:
        raise ValueError(f"view {view!r}: expected one of {VIEWS}")
    renderer.aim(head_points(face), view=view)


def head_points(face: Face) -> np.ndarray:
    """The skin above the neck: what a camera aimed at the head frames."""
    skin = face.vertices[face.parts["skin"]]
    chin = face.feature_points.get("2.1")
    keep = skin[:, 1] > chin[1] - 0.25 * np.ptp(skin[:, 1]) if chin is not None else slice(None)
    return skin[keep]


def _progress(frames: Iterator[np.ndarray], total: int | None, show: bool) -> Iterator[np.ndarray]:
    """Pass frames through, with a progress bar on stderr (rich's; when ``show``: a terminal)."""
    if not show:
        yield from frames
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    columns = (TextColumn("rendering"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("render", total=total or None)
        for frame in frames:
            yield frame
            bar.advance(task)
