"""A key table for headless windows (``window.keys``), as moderngl-window's own windows carry."""


class WindowKeys:
    """The key names the live view, the player and moderngl-window's ImGui integration look up."""

    ACTION_PRESS, ACTION_RELEASE = "press", "release"
    R, N, C, K, M, H, Q, ESCAPE = "r", "n", "c", "k", "m", "h", "q", "escape"
    TAB, LEFT, RIGHT, UP, DOWN, PAGE_UP, PAGE_DOWN = "tab", "left", "right", "up", "down", "pgup", "pgdn"
    HOME, END, DELETE, SPACE, BACKSPACE, ENTER = "home", "end", "delete", "space", "backspace", "enter"
