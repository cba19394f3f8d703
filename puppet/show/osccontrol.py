"""OSC control addresses: the control API for lighting desks and show-control software (QLab...).

With ``--osc-control HOST:PORT`` the show server also listens for OSC over UDP and turns each
message into the API message it stands for, checked and answered the same way (``ShowServer.answer``;
OSC has no replies, so a refusal is counted and said once on stderr per reason):

=====================================  ====================================================
``/puppet/set/<channel> <number>``     ``{"type": "set", "channels": {channel: number}}``
``/puppet/set <channel> <number> ...`` several channels at once
``/puppet/trigger/<name>``             ``{"type": "trigger", "name": name}`` (fire)
``/puppet/trigger/<name> <action>``    ``press``, ``release`` or ``fire``; a number: non-zero
                                       presses, zero releases (a desk's button sends 1 then 0)
``/puppet/record/start``, ``.../stop`` ``{"type": "record", "action": ...}``; also
                                       ``/puppet/record <number>``: non-zero starts, zero stops
``/puppet/neutral``                    ``{"type": "neutral"}``
=====================================  ====================================================

Datagrams are parsed with the OSC device's bounded reader (``devices.osc_packet``); OSC has no
token, so it listens on loopback unless told otherwise, and only when asked.
"""

from __future__ import annotations

import asyncio
import sys
from typing import Any

from devices.osc_packet import OscFormatError, parse_datagram
from puppet.show import api

PREFIX = "/puppet/"


def api_message(address: str, arguments: list) -> dict:
    """The checked API message an OSC message stands for; ApiError naming what is wrong."""
    if not address.startswith(PREFIX):
        raise api.ApiError(f"OSC {address!r:.80}: control addresses start with {PREFIX}")
    head, _, rest = address[len(PREFIX):].partition("/")
    if head == "set":
        return api.check({"type": "set", "channels": _channels(address, rest, arguments)})
    if head == "trigger" and rest:
        action = arguments[0] if arguments else "fire"
        if _number(action):
            action = "press" if action else "release"
        return api.check({"type": "trigger", "name": rest, "action": action})
    if head == "record":
        action = rest or (("start" if arguments[0] else "stop") if arguments and _number(arguments[0]) else None)
        return api.check({"type": "record", "action": action})
    if head == "neutral" and not rest:
        return api.check({"type": "neutral"})
    raise api.ApiError(f"OSC {address!r:.80}: expected {PREFIX}set, trigger/NAME, record/start|stop or neutral")


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _channels(address: str, name: str, arguments: list) -> dict:
    if name:
        if len(arguments) != 1 or not _number(arguments[0]):
            raise api.ApiError(f"OSC {address!r:.80}: expected one number, got {arguments!r:.80}")
        return {name: arguments[0]}
    if len(arguments) % 2 or not arguments:
        raise api.ApiError(f"OSC {address!r:.80}: expected channel, number pairs, got {arguments!r:.80}")
    return dict(zip(arguments[::2], arguments[1::2]))


class OscControl(asyncio.DatagramProtocol):
    """The datagram endpoint (in the show server's loop) that hands OSC messages to ``answer``."""

    def __init__(self, answer) -> None:
        self.answer = answer
        self.counts = {"messages": 0, "refused": 0}
        self._said: set[str] = set()

    def datagram_received(self, data: bytes, addr: tuple) -> None:
        try:
            messages = parse_datagram(data)
        except OscFormatError as exc:
            self._refused(f"a datagram from {addr[0]} that is not OSC: {exc}")
            return
        for address, arguments in messages:
            self.counts["messages"] += 1
            try:
                message = api_message(address, arguments)
            except api.ApiError as exc:
                self._refused(str(exc))
                continue
            asyncio.ensure_future(self._send(message))

    async def _send(self, message: dict) -> None:
        reply, _ = await self.answer(message)
        if not reply["ok"]:
            self._refused(f"OSC {message['type']}: {reply['error']}")

    def _refused(self, reason: str) -> None:
        self.counts["refused"] += 1
        if reason not in self._said and len(self._said) < 100:
            self._said.add(reason)
            print(f"osc control: refused {reason}", file=sys.stderr)
