"""The live window's cockpit: what a puppeteer needs to see, drawn in the window itself.

Dear ImGui (``imgui-bundle``, through moderngl-window's integration) draws over the face after it
is rendered into the window's framebuffer:

* **fps and input-to-photon latency**: the numbers and a rolling graph of the last ``HISTORY``
  frames each;
* **devices**: each one's state, and while it is LOST the reason its adapter gave (port missing,
  permission denied, unplugged); an audio input also gets a level meter (dBFS, the noise gate's
  threshold marked by the bar's colour) and its overrun and underrun counts;
* **triggers**: each of the mapping's triggers with its key or channel and its level, lit while
  it is on (``puppet.live.triggers``);
* **REC**: the take's name and how long it has been recording; for a layered pass, the base take
  playing under it (its frame) and what is armed;
* a **notice** line: the steps of a calibration run from the window (K), then its result (red, for
  20 s, when channels were left as they were or nothing was written);
* **channel monitor** (M): per channel a bar of its raw value within its calibrated range and one
  of its shaped value's size (the signed value written on it), with the first target it drives;
* **the keys**.

H hides it. Hidden, a frame only appends its fps and latency to the graphs' history (``tick``):
no ImGui call, no device or channel read, so the overlay costs nothing (``tools/bench/bench_overlay.py``
measures it). It draws on any moderngl-window window, headless (EGL) ones included, so tests and
screenshots need no display.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from puppet.view.imguilayer import ImguiLayer

FAILURE_RGBA = (1.0, 0.3, 0.3, 1.0)
"""The colour of a notice that says something failed (a calibration that left channels as they were)."""

HISTORY = 240
"""Frames the rolling fps and latency graphs show."""

KEYS = (("R", "record / stop"), ("N", "neutral"), ("C", "re-centre sticks"), ("K", "calibrate"),
        ("M", "channel monitor"), ("H", "hide this"), ("Q Esc", "quit"))


@dataclass
class DeviceLine:
    """One device as the cockpit shows it."""

    name: str
    state: str
    reason: str = ""
    level_db: float | None = None   # an audio input's newest level (None: not an audio input)
    gate_db: float | None = None
    overruns: int = 0
    underruns: int = 0

    @property
    def meter(self) -> float:
        """The level as a bar's fill: -60 dBFS empty, 0 dBFS full."""
        return 0.0 if self.level_db is None else min(1.0, max(0.0, (self.level_db + 60.0) / 60.0))


class Cockpit(ImguiLayer):
    """The overlay on one window (module docstring); ``draw`` once a frame, after the face."""

    def __init__(self, window: Any) -> None:
        super().__init__(window)
        self.monitor = False
        self.fps: deque[float] = deque(maxlen=HISTORY)
        self.latency: deque[float] = deque(maxlen=HISTORY)

    def tick(self, fps: float, latency_ms: float | None) -> None:
        """Every frame, shown or hidden: the graphs' history (so they are whole when shown again)."""
        self.fps.append(fps)
        self.latency.append(latency_ms or 0.0)

    def draw(self, fps: float, latency_ms: float | None, devices: Iterable[DeviceLine],
             recording: tuple[str, float] | None, channels: Iterable[Any], notice: str = "",
             layer: str | None = None, triggers: Iterable[Any] = (), failed: bool = False) -> None:
        """Draw the cockpit over the current framebuffer (nothing when hidden: the caller skips
        gathering what it shows too). ``recording``: (take name, seconds) while a take runs;
        ``channels``: ``Mapping.channels()``; ``notice``: a line for the performer (the window's
        calibration steps, its result); ``layer``: a layered pass's base take and what is armed
        (``LiveSession.layer_status``); ``triggers``: ``Mapping.trigger_states``; ``failed``: the
        notice says a failure (drawn red)."""
        if not self.visible:
            return
        imgui = self.begin()
        imgui.new_frame()
        self._status(fps, latency_ms, list(devices), recording, notice, layer, failed)
        self._triggers(list(triggers))
        if self.monitor:
            self._monitor(list(channels))
        imgui.render()
        self.renderer.render(imgui.get_draw_data())

    # -- panels --------------------------------------------------------------------------------

    def _status(self, fps: float, latency_ms: float | None, devices: list[DeviceLine],
                recording: tuple[str, float] | None, notice: str, layer: str | None = None,
                failed: bool = False) -> None:
        imgui = self.imgui
        imgui.set_next_window_pos((8, 8), imgui.Cond_.first_use_ever)
        imgui.set_next_window_bg_alpha(0.7)
        flags = imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_focus_on_appearing
        imgui.begin("facepuppet", None, flags)
        latency = "-- ms" if latency_ms is None else f"{latency_ms:.1f} ms"
        imgui.text(f"{fps:5.1f} fps   input to photon {latency}")
        imgui.plot_lines("##fps", np.asarray(self.fps, dtype=np.float32), graph_size=(220, 32),
                         overlay_text="fps", scale_min=0.0)
        imgui.plot_lines("##latency", np.asarray(self.latency, dtype=np.float32), graph_size=(220, 32),
                         overlay_text="latency ms", scale_min=0.0)
        for device in devices:
            colour = (0.4, 1.0, 0.4, 1.0) if device.state == "open" else (1.0, 0.45, 0.35, 1.0)
            imgui.text_colored(colour, f"{device.name}: {device.state}")
            if device.reason:
                imgui.same_line()
                imgui.text_wrapped(device.reason)
            if device.level_db is not None:
                self._meter(device)
        if recording is not None:
            name, seconds = recording
            imgui.text_colored((1.0, 0.2, 0.2, 1.0), f"REC {name}  {int(seconds) // 60}:{seconds % 60:04.1f}")
        if layer is not None:
            imgui.text_colored((0.55, 0.8, 1.0, 1.0), f"layer {layer}" if recording else
                               f"layer {layer} (R records a pass)")
        if notice:
            imgui.text_colored(FAILURE_RGBA if failed else (1.0, 0.85, 0.3, 1.0), notice)
        imgui.separator()
        for k, (key, what) in enumerate(KEYS):
            if k % 2:
                imgui.same_line(150)
            imgui.text_disabled(f"{key:>5} {what}")
        imgui.end()

    def _triggers(self, triggers: list[Any]) -> None:
        """The triggers' panel: a bar of each one's level (lit while on), its key or channel."""
        if not triggers:
            return
        imgui = self.imgui
        imgui.set_next_window_pos((8, self.window.size[1] - 8), imgui.Cond_.first_use_ever, (0.0, 1.0))
        imgui.set_next_window_bg_alpha(0.7)
        imgui.begin("triggers", None, imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_focus_on_appearing)
        for trigger in triggers:
            lit = (1.0, 0.75, 0.2, 1.0) if trigger.active else (0.45, 0.45, 0.45, 1.0)
            imgui.push_style_color(imgui.Col_.plot_histogram, lit)
            imgui.progress_bar(trigger.level / trigger.strength, (120, 0), trigger_label(trigger))
            imgui.pop_style_color()
            imgui.same_line()
            imgui.text_disabled(trigger.source or "by name")
        imgui.end()

    def _meter(self, device: DeviceLine) -> None:
        """An audio input's level bar (green above its gate, grey below) and its xruns."""
        imgui = self.imgui
        above = device.gate_db is not None and device.level_db > device.gate_db
        colour = (0.3, 0.85, 0.35, 1.0) if above else (0.5, 0.5, 0.5, 1.0)
        imgui.push_style_color(imgui.Col_.plot_histogram, colour)
        imgui.progress_bar(device.meter, (160, 0), f"{device.level_db:.0f} dBFS")
        imgui.pop_style_color()
        if device.overruns or device.underruns:
            imgui.same_line()
            imgui.text_colored((1.0, 0.85, 0.3, 1.0), f"over {device.overruns} under {device.underruns}")

    def _monitor(self, channels: list[Any]) -> None:
        imgui = self.imgui
        width = self.window.size[0]
        imgui.set_next_window_pos((width - 8, 8), imgui.Cond_.first_use_ever, (1.0, 0.0))
        imgui.set_next_window_bg_alpha(0.7)
        imgui.begin("channels", None, imgui.WindowFlags_.always_auto_resize)
        for channel in channels:
            imgui.text(channel.name)
            imgui.same_line(90)
            raw = channel.raw_fraction
            imgui.progress_bar(0.0 if raw is None else float(np.clip(raw, 0.0, 1.0)), (80, 0),
                               "-" if channel.raw is None else f"{channel.raw:.4g}")
            imgui.same_line()
            shaped = float(np.clip(channel.value, -1.0, 1.0))
            imgui.progress_bar(abs(shaped), (60, 0), f"{shaped:+.2f}")
            if channel.targets:
                imgui.same_line()
                imgui.text_disabled(targets_label(channel.targets))
        imgui.end()


def trigger_label(trigger: Any) -> str:
    """A trigger as its bar says it: name, mode, and ``on`` while a toggle is latched."""
    return f"{trigger.name} ({trigger.mode}{', on' if trigger.latched else ''})"


def targets_label(targets: tuple[str, ...], width: int = 26) -> str:
    """What a channel drives, as the monitor says it: its first target, and how many more."""
    more = len(targets) - 1
    return targets[0][:width] + (f" and {more} more target{'s' * (more > 1)}" if more else "")


def device_lines(states: Mapping[str, Any], devices: Mapping[str, Any]) -> list[DeviceLine]:
    """Each device's state (``LiveFrame.states``; "unavailable" for one lost before it ever opened)
    and, when it is not open, the reason its adapter gave; an audio input's level, gate and xruns."""
    lines = []
    for name, state in states.items():
        text = getattr(state, "value", str(state)).lower()
        device = devices.get(name)
        counters = getattr(device, "counters", None)
        reason = counters.last_error if counters is not None and text != "open" else ""
        if text == "lost" and counters is not None and not (counters.samples or counters.reconnects):
            text = "unavailable"  # never opened: "lost" would say it had been there (no MIDI system)
        line = DeviceLine(name, text, reason)
        if hasattr(device, "level_db"):
            line.level_db, line.gate_db = device.level_db, device.gate
            line.overruns, line.underruns = counters.overruns, counters.underruns
        lines.append(line)
    return lines
