"""A Dear ImGui layer drawn over one window's face: its own context and renderer, shown or hidden
with H. The live window's cockpit (``puppet.view.overlay``) and the player's status line
(``puppet.view.playbar``) are each one."""

from __future__ import annotations

import time
from typing import Any


class ImguiLayer:
    """An ImGui context on ``window``; ``begin`` starts a frame of it (nothing written beside the
    user's takes: no imgui.ini)."""

    def __init__(self, window: Any) -> None:
        from imgui_bundle import imgui
        from moderngl_window.integrations.imgui_bundle import ModernglWindowRenderer

        self.imgui = imgui
        self.context = imgui.create_context()
        imgui.get_io().set_ini_filename("")
        self.renderer = ModernglWindowRenderer(window)
        self.window = window
        self.visible = True
        self._last = time.perf_counter()

    def toggle(self) -> None:
        """H: show or hide the layer."""
        self.visible = not self.visible

    def begin(self) -> Any:
        """Make this layer's context current and give it the time since its last frame and the
        window's size; returns ``imgui`` for the frame's calls."""
        imgui = self.imgui
        imgui.set_current_context(self.context)
        now = time.perf_counter()
        io = imgui.get_io()
        io.delta_time = max(now - self._last, 1e-4)
        io.display_size = self.window.size
        self._last = now
        return imgui

    def release(self) -> None:
        self.renderer.shutdown()
        self.imgui.destroy_context(self.context)
