"""The player's status line, drawn in its window: which frame, what time, and whether it is paused.

``puppet play`` says the frame and "paused" in the window's title too, but many window managers
show no title (tiling ones, full screen, a screenshot of the window), so the window itself carries
it: a line at the bottom left, ``frame 12/98   0:00.44 / 0:03.92   25 fps   paused``, drawn with
Dear ImGui over the face as the live window's cockpit is (``puppet.view.overlay``). H hides it.
"""

from __future__ import annotations

from puppet.view.imguilayer import ImguiLayer


def clock_text(seconds: float) -> str:
    """``m:ss.ss``: a time into a take as the player says it."""
    return f"{int(seconds) // 60}:{seconds % 60:05.2f}"


def play_status(frame: int, total: int | None, fps: float, paused: bool) -> str:
    """``frame 12/98   0:00.44 / 0:03.92   25 fps   paused`` (frames counted from 1; the time is
    the frame's start; "?" for a total not known yet, and then no length either)."""
    length = "?" if total is None else clock_text(total / fps)
    parts = [f"frame {frame + 1}/{'?' if total is None else total}",
             f"{clock_text(frame / fps)} / {length}", f"{fps:g} fps", "paused" if paused else "playing"]
    return "   ".join(parts)


class PlayBar(ImguiLayer):
    """The status line on one window; ``draw`` after the face, before the buffer swap."""

    def draw(self, text: str) -> None:
        """The line over the current framebuffer (nothing while hidden)."""
        if not self.visible:
            return
        imgui = self.begin()
        for _ in range(2 if imgui.get_frame_count() == 0 else 1):  # ImGui measures a new window unseen
            imgui.new_frame()
            imgui.set_next_window_pos((8, self.window.size[1] - 8), imgui.Cond_.always, (0.0, 1.0))
            imgui.set_next_window_bg_alpha(0.7)
            flags = (imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_focus_on_appearing
                     | imgui.WindowFlags_.no_title_bar | imgui.WindowFlags_.no_inputs)
            imgui.begin("play", None, flags)
            imgui.text(text)
            imgui.end()
            imgui.render()
        self.renderer.render(imgui.get_draw_data())
