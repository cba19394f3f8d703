"""OSC over UDP: phone face trackers, TouchOSC faders, anything that speaks Open Sound Control.

``osc://127.0.0.1:39539`` binds a UDP socket (loopback unless another address is given: a live
rig should not listen on the network by accident) and turns OSC messages into channels:

* an ordinary message ``/fader/1 0.5`` becomes channel ``fader/1`` = 0.5 (its first numeric
  argument; a message whose arguments hold no number is counted as a bad frame);
* the VMC protocol's blendshape messages, which face trackers (ARKit via iFacialMocap,
  Waidayo, ...) send: ``/VMC/Ext/Blend/Val <name> <value>`` sets a pending blendshape and
  ``/VMC/Ext/Blend/Apply`` emits every pending one as a single Sample, so a tracker frame stays a
  frame;
* bundles are unpacked in order.

Packets are parsed with python-osc's own packet parser; a datagram that is not OSC is counted in
``bad_frames`` and skipped.
"""

from __future__ import annotations

import socket
from collections.abc import Mapping

from pythonosc.osc_packet import OscPacket, ParseError

from .base import Device, DeviceError, Url

BLEND_VALUE = "/VMC/Ext/Blend/Val"
BLEND_APPLY = "/VMC/Ext/Blend/Apply"
TIMEOUT = 0.05
DATAGRAM = 65536


class OscDevice(Device):
    """Channels from OSC messages arriving on a UDP port."""

    def __init__(self, name: str, host: str = "127.0.0.1", port: int = 39539) -> None:
        super().__init__(name)
        self.host, self.port = host, port
        self._socket: socket.socket | None = None
        self._pending: dict[str, float] = {}

    @classmethod
    def from_url(cls, url: Url, name: str) -> OscDevice:
        host, _, port = url.target.strip("/").rpartition(":")
        if not port.isdigit() or int(port) > 65535:
            raise DeviceError(f"osc URL: expected osc://HOST:PORT (e.g. osc://127.0.0.1:39539), got {url.target!r}")
        return cls(name, host or "127.0.0.1", int(port))

    @property
    def address(self) -> tuple[str, int]:
        """Where the socket is bound (the real port when 0 was asked for)."""
        if self._socket is None:
            return self.host, self.port
        return self._socket.getsockname()[:2]

    def _open(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.settimeout(TIMEOUT)
        try:
            sock.bind((self.host, self.port))
        except OSError:
            sock.close()
            raise
        self.port = sock.getsockname()[1]
        self._socket = sock

    def _read(self) -> list[Mapping[str, float]]:
        try:
            datagram = self._socket.recv(DATAGRAM)
        except socket.timeout:
            return []
        try:
            messages = [timed.message for timed in OscPacket(datagram).messages]
        except ParseError:
            self.counters.bad_frames += 1
            return []
        out = []
        for message in messages:
            reading = self._reading(message.address, message.params)
            if reading:
                out.append(reading)
        return out

    def _reading(self, address: str, params: list) -> dict[str, float] | None:
        """One message's channels, or None (pending blendshapes, or nothing usable)."""
        if address == BLEND_VALUE:
            if len(params) >= 2 and isinstance(params[0], str) and _is_number(params[1]):
                self._pending[params[0]] = float(params[1])
            else:
                self.counters.bad_frames += 1
            return None
        if address == BLEND_APPLY:
            applied, self._pending = self._pending, {}
            return applied or None
        number = next((p for p in params if _is_number(p)), None)
        if number is None:
            self.counters.bad_frames += 1
            return None
        return {address.lstrip("/"): float(number)}

    def _close(self) -> None:
        if self._socket is not None:
            self._socket.close()
            self._socket = None


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
