"""``api://``: the channels a program sets through the control API (``puppet.show``).

A mapping that names an ``api://`` device routes its channels like any other's: a script's
``{"type": "set", "channels": {"smile": 0.8}}`` becomes a Sample of channel ``smile`` of that
device (``devices.pushed_device``), so the take logs it and a replay gives it back. The URL has
no target and no options: ``api://``.
"""

from __future__ import annotations

from devices.pushed_device import PushedDevice, PushedTwin


class ApiDevice(PushedDevice):
    """Channels set by the control API's clients."""


class ApiTwin(PushedTwin):
    DEVICE = ApiDevice


DEVICE, TWIN = ApiDevice, ApiTwin
