"""``keys://``: the live window's keyboard as a device, so a mapping can put poses on keys.

While a live window has the focus, every key press and release that is not one of the window's
own keys (``WINDOW_KEYS``: record, neutral, re-centre, calibrate, monitor, hide, quit; F11 is the
window's full screen) is pushed to each ``keys://`` device of the session
(``devices.pushed_device``): channel = the key's name, 1.0 on press, 0.0 on release. So a key is
a button channel like any other, routed by the mapping (a trigger's ``source: keys.1``), logged
in the take and given back by a replay. The URL has no target and no options: ``keys://``.

The channels are ``KEY_NAMES``: the digits ``"0"``..``"9"`` (the row above the letters), the
letters ``"a"``..``"z"`` except the window's own, and ``"f1"``..``"f12"`` except ``"f11"``. A
mapping naming any other channel of a keys device is refused when it is loaded
(``unknown_channel``), and so is a push of one.
"""

from __future__ import annotations

import string
from collections.abc import Mapping

from devices.base import Url, closest_hint
from devices.pushed_device import PushedDevice, PushedTwin

WINDOW_KEYS = frozenset("rnckmhq")
"""The letters the live window keeps for itself (``puppet.view.livewindow``): never channels."""

KEY_ATTRIBUTES: dict[str, str] = {
    **{f"NUMBER_{d}": d for d in string.digits},
    **{c.upper(): c for c in string.ascii_lowercase if c not in WINDOW_KEYS},
    **{f"F{n}": f"f{n}" for n in range(1, 13) if n != 11},
}
"""moderngl-window's key table attribute (``window.keys.NUMBER_1``) -> the channel it is."""

KEY_NAMES = tuple(KEY_ATTRIBUTES.values())
"""Every channel a ``keys://`` device has."""


def key_problem(channel: str) -> str | None:
    """Why ``channel`` is not a key of a ``keys://`` device (None when it is one)."""
    if channel in KEY_NAMES:
        return None
    if channel.lower() in WINDOW_KEYS:
        return (f"key {channel!r} is the live window's own (R record, N neutral, C re-centre, K calibrate, "
                f"M monitor, H hide, Q quit): expected another key")
    if channel.lower() in KEY_NAMES:
        return f"key names are lower case: expected {channel.lower()!r}, got {channel!r}"
    return (f"expected a key: a digit 0-9, a letter a-z other than the window's own (r n c k m h q), "
            f"or f1-f12 but f11, got {channel!r}{closest_hint(channel, KEY_NAMES)}")


def key_channels(keys: object) -> dict[object, str]:
    """A window's key table (moderngl-window's ``window.keys``) as key code -> channel name, for
    the keys its backend has (an absent key is ``"undefined"`` there)."""
    out = {}
    for attribute, name in KEY_ATTRIBUTES.items():
        code = getattr(keys, attribute, None)
        if code is not None and code != "undefined":
            out[code] = name
    return out


class KeysDevice(PushedDevice):
    """The live window's keys, pushed in by the window as they are pressed and released."""

    @classmethod
    def unknown_channel(cls, url: Url, channel: str) -> str | None:
        return key_problem(channel)

    def push(self, values: Mapping[str, float]) -> None:
        """Queue one reading; a channel that is not a key is a ValueError naming it (nothing queued)."""
        for channel in values if isinstance(values, Mapping) else ():
            problem = key_problem(channel) if isinstance(channel, str) else None
            if problem:
                raise ValueError(f"{self.name}: {problem}")
        super().push(values)


class KeysTwin(PushedTwin):
    DEVICE = KeysDevice


DEVICE, TWIN = KeysDevice, KeysTwin
