"""The last value made under each name, kept while its key stays the same.

A part's rigid motion follows a few FAPs; while they hold (a held jaw, still eyes) the motion is
the same every frame, so it is made once and shared from frame to frame. The values are made
read-only, since every frame that reuses one holds the same array.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


class LastMade:
    """``get(name, key, make)``: ``make()``'s value for ``name``, made again only when ``key``
    (bytes: what the value is a function of) differs from the last call's for that name."""

    def __init__(self) -> None:
        self._last: dict[str, tuple[bytes, np.ndarray]] = {}

    def get(self, name: str, key: bytes, make: Callable[[], np.ndarray]) -> np.ndarray:
        last = self._last.get(name)
        if last is None or last[0] != key:
            value = make()
            value.setflags(write=False)
            last = self._last[name] = (key, value)
        return last[1]
