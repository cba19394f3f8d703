"""What the live window's cockpit costs a frame: shown, shown with the channel monitor, and hidden.

    taskset -c 1 env OPENBLAS_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python tools/bench/bench_overlay.py [--rounds 8] [--frames 40]

One live session (the shipped slider box mapping on the simulated box at 200 Hz) drawn into a
headless (EGL) window of the live window's size, 960x720: the modes take turns, ``--frames``
frames each per round, so a busy machine slows them alike. For each mode it prints the median
whole frame (``LiveView.step``: session frame, face drawn, cockpit, swap) and the median of the
cockpit's own call (``LiveView._draw_cockpit``: gathering what it shows, ImGui, its draw).
Hidden, the cockpit call is only the graphs' history (``Cockpit.tick``), and the whole frame is
the face's alone.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

import moderngl_window

from puppet.io.shipped import shipped_mappings
from puppet.view.livewindow import LiveView, open_session

SIM_BOX = {"box": "sim://joystick?protocol=ascii&rate=200&channels=6"}
MODES = {"shown": (True, False), "shown + monitor": (True, True), "hidden": (False, True)}


def _timed_cockpit(live: LiveView, times: list[float]) -> None:
    """Time every ``_draw_cockpit`` call into ``times`` (seconds)."""
    draw = live._draw_cockpit

    def timed(states):
        start = time.perf_counter()
        draw(states)
        times.append(time.perf_counter() - start)

    live._draw_cockpit = timed


def measure(rounds: int, frames: int, size: tuple[int, int] = (960, 720)) -> dict[str, dict[str, float]]:
    """Median frame and cockpit-call times in ms per mode (``MODES``), the modes taking turns."""
    window = moderngl_window.get_local_window_cls("headless")(size=size, gl_version=(3, 3), backend="egl")
    frame_ms: dict[str, list[float]] = {mode: [] for mode in MODES}
    cockpit_ms: dict[str, list[float]] = {mode: [] for mode in MODES}
    with tempfile.TemporaryDirectory() as takes:
        session = open_session(shipped_mappings()["arduino_sliders"], devices=SIM_BOX, record_root=takes)
        live = LiveView(session, window)
        calls: list[float] = []
        _timed_cockpit(live, calls)
        try:
            for _ in range(10):  # the renderer, shaders and ImGui's font atlas made before timing
                live.step()
            for _ in range(rounds):
                for mode, (visible, monitor) in MODES.items():
                    live.cockpit.visible, live.cockpit.monitor = visible, monitor
                    live.step()  # the first frame after a switch is not counted
                    calls.clear()
                    for _ in range(frames):
                        start = time.perf_counter()
                        live.step()
                        frame_ms[mode].append((time.perf_counter() - start) * 1e3)
                    cockpit_ms[mode] += [t * 1e3 for t in calls]
        finally:
            live.close()
            session.close()
    return {mode: {"frame_ms": statistics.median(frame_ms[mode]), "cockpit_ms": statistics.median(cockpit_ms[mode])}
            for mode in MODES}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--frames", type=int, default=40)
    args = parser.parse_args()
    results = measure(args.rounds, args.frames)
    hidden = results["hidden"]["frame_ms"]
    print(f"{'mode':18} {'frame ms':>9} {'cockpit ms':>11} {'frame / hidden':>15}")
    for mode, r in results.items():
        print(f"{mode:18} {r['frame_ms']:9.2f} {r['cockpit_ms']:11.4f} {r['frame_ms'] / hidden:15.2f}")


if __name__ == "__main__":
    main()
