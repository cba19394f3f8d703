"""The last value made under each name, kept while its key stays the same.

A part's rigid motion follows a few FAPs, the muscle fold guard's correction the muscles' share;
while they hold (a held jaw, still eyes, a held pose) the value is the same every frame, so it is
made once and shared from frame to frame. Its arrays are made read-only, since every frame that
reuses one holds the same arrays.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Made = np.ndarray | tuple[np.ndarray, ...]


class LastMade:
    """``get(name, key, make)``: ``make()``'s value (an array, or a tuple of arrays) for ``name``,
    made again only when ``key`` (bytes: what the value is a function of) differs from the last
    call's for that name."""

    def __init__(self) -> None:
        self._last: dict[str, tuple[bytes, Made]] = {}

    def get(self, name: str, key: bytes, make: Callable[[], Made]) -> Made:
        last = self._last.get(name)
        if last is None or last[0] != key:
            value = make()
            for array in value if isinstance(value, tuple) else (value,):
                array.setflags(write=False)
            last = self._last[name] = (key, value)
        return last[1]
