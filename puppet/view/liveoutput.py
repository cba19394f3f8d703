"""Where a live frame goes besides the window: outputs, and the live loop with no window at all.

A ``LiveOutput`` (the show server, ``puppet.show.server.ShowServer``; the NDI source,
``puppet.show.ndi.NdiOutput``; the program window's process, ``puppet.show.program``) is handed every frame's
vertices and the rig's status after the frame is drawn (``publish``), and gets a turn on the live
loop's thread before each frame (``service``: what it queued that changes the session runs
there, between frames). Outputs sit above this layer, so the loop knows them only by these calls.

``HeadlessLive`` runs the same loop with no window, for a rig that only serves its face (``puppet
live --serve ... --no-window``): a frame as soon as a Sample arrives (``LiveSession.wait_for_input``),
at most ``MAX_FPS`` a second, and one at least every ``1 / IDLE_FPS`` s so the face keeps
moving on its own (smoothing settling, idle life).
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterable, Sequence
from typing import Any, Protocol

import numpy as np

from puppet.io.takes import open_take
from puppet.live.session import close_each

MAX_FPS = 60
IDLE_FPS = 30


class LiveOutput(Protocol):
    def publish(self, vertices: np.ndarray, status: dict | None = None) -> None: ...

    def service(self) -> None: ...

    def close(self) -> None: ...


def live_status(session: Any, stats: Any, frame: Any) -> dict:
    """The rig's status as outputs report it: devices and their states, the measured fps and
    latency, the take being recorded (None when not), the frames drawn and each trigger's level."""
    take = session.take_folder
    return {"devices": {name: state.name.lower() for name, state in session.states.items()},
            "triggers": {t.name: round(t.level, 3)
                         for t in session.mapping.trigger_states(frame.pose.t_ns or frame.t_ns)},
            "fps": round(stats.fps, 1),
            "latency_ms": None if stats.latency_ms is None else round(stats.latency_ms, 2),
            "recording": None if take is None else take.name, "frames": session.frames}


def publish(outputs: Sequence[LiveOutput], frame: Any, status: dict) -> None:
    for output in outputs:
        output.publish(frame.vertices, status)


def close_outputs(outputs: Iterable[LiveOutput]) -> None:
    """Close each output, even if another fails; the first failure is raised after."""
    close_each(outputs)


def saved_line(folder: str | os.PathLike) -> str:
    """A saved take as the terminal says it: its folder, length, frames and what it keeps."""
    meta = open_take(folder).meta
    frames, fps = meta.get("frames") or 0, meta["fps"]
    sound = ", with its sound" if meta.get("sound") else ""
    return (f"{folder} ({frames / fps:.1f} s, {frames} frames at {fps} fps, "
            f"{meta.get('samples') or 0} readings{sound})")


class HeadlessLive:
    """A LiveSession's loop with no window: frames for the outputs only; ``run()`` until Ctrl+C."""

    def __init__(self, session: Any, outputs: Sequence[LiveOutput], stats: Any) -> None:
        self.session, self.outputs, self.stats = session, list(outputs), stats
        self._take = None

    def step(self) -> None:
        for output in self.outputs:
            output.service()
        frame = self.session.frame()
        self.stats.drawn(time.monotonic_ns(), frame.newest_sample_ns, frame.n_samples > 0)
        publish(self.outputs, frame, live_status(self.session, self.stats, frame))
        self._follow_take()

    def run(self) -> None:
        last = 0.0
        try:
            while True:
                self.session.wait_for_input(1.0 / IDLE_FPS)
                wait = last + 1.0 / MAX_FPS - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                last = time.monotonic()
                self.step()
        finally:
            try:
                if self.session.recording:
                    self.session.stop_recording()
                    self._follow_take()
            finally:
                close_outputs(self.outputs)

    def _follow_take(self) -> None:
        folder = self.session.take_folder
        if folder != self._take:
            if self._take is not None:
                print(f"take saved: {saved_line(self._take)}" if not self.session.record_error
                      else f"take not complete: {self.session.record_error}", file=sys.stderr)
            if folder is not None:
                print(f"recording {folder.resolve()}", file=sys.stderr)
            self._take = folder
