"""A key table for headless windows (``window.keys``), as moderngl-window's own windows carry."""


class WindowKeys:
    """The key names the live view, the player and moderngl-window's ImGui integration look up."""

    ACTION_PRESS, ACTION_RELEASE = "press", "release"
    R, N, C, K, M, H, Q, ESCAPE = "r", "n", "c", "k", "m", "h", "q", "escape"
    TAB, LEFT, RIGHT, UP, DOWN, PAGE_UP, PAGE_DOWN = "tab", "left", "right", "up", "down", "pgup", "pgdn"
    HOME, END, DELETE, SPACE, BACKSPACE, ENTER = "home", "end", "delete", "space", "backspace", "enter"
    NUMBER_0, NUMBER_1, NUMBER_2, NUMBER_3, NUMBER_4 = "0", "1", "2", "3", "4"
    NUMBER_5, NUMBER_6, NUMBER_7, NUMBER_8, NUMBER_9 = "5", "6", "7", "8", "9"
    A, F1, F11 = "a", "f1", "f11"
