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

Datagrams are parsed with bounds (``devices.osc_packet``: a sender on the network can make the
reader neither loop, recurse nor allocate); one that is not well-formed OSC is counted in
``bad_frames`` and skipped, and the device goes on reading. At most ``MAX_PENDING`` blendshapes
wait for their Apply: a sender that never applies cannot grow them without bound.

``OscTwin`` is the wire twin (``devices.twin``): an ``OscDevice`` on a free loopback port, sent
each logged reading as OSC over UDP.
"""

from __future__ import annotations

import socket
from collections.abc import Mapping
from typing import Any

from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from devices.base import Device, DeviceError, Url
from devices.osc_packet import OscFormatError, parse_datagram
from devices.twin import Twin

BLEND_VALUE = "/VMC/Ext/Blend/Val"
BLEND_APPLY = "/VMC/Ext/Blend/Apply"
TIMEOUT = 0.05
DATAGRAM = 65536
MAX_PENDING = 1024  # blendshapes waiting for an Apply (ARKit sends 52)


class OscDevice(Device):
    """Channels from OSC messages arriving on a UDP port."""

    def __init__(self, name: str, host: str = "127.0.0.1", port: int = 39539) -> None:
        super().__init__(name)
        self.host, self.port = host, port
        self._socket: socket.socket | None = None
        self._pending: dict[str, float] = {}

    @classmethod
    def from_url(cls, url: Url, name: str) -> OscDevice:
        cls.check_options(url)
        host, _, port = url.target.strip("/").rpartition(":")
        if not port.isdigit() or int(port) > 65535:
            raise DeviceError(f"osc URL: expected osc://HOST:PORT (e.g. osc://127.0.0.1:39539), got {url.target!r}")
        return cls(name, host or "127.0.0.1", int(port))

    @property
    def address(self) -> tuple[str, int]:
        """Where the socket is bound (the real port when 0 was asked for)."""
        if self._socket is None:
            return self.host, self.port
        host, port = self._socket.getsockname()[:2]
        return host, port

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
            datagram = self._socket.recv(DATAGRAM)  # type: ignore[union-attr]  # set by _open
        except TimeoutError:
            return []
        try:
            messages = parse_datagram(datagram)
        except OscFormatError:
            self.counters.bad_frames += 1
            return []
        out: list[Mapping[str, float]] = []
        for address, params in messages:
            reading = self._reading(address, params)
            if reading:
                out.append(reading)
        return out

    def _reading(self, address: str, params: list[Any]) -> dict[str, float] | None:
        """One message's channels, or None (pending blendshapes, or nothing usable)."""
        if address == BLEND_VALUE:
            usable = len(params) >= 2 and isinstance(params[0], str) and _is_number(params[1])
            if usable and (params[0] in self._pending or len(self._pending) < MAX_PENDING):
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


class OscTwin(Twin):
    """``osc://`` wires: an ``OscDevice`` bound on a free loopback port (not the logged one, which
    a live rig may hold), sent each logged reading in one datagram built by python-osc, its
    values as doubles (OSC type ``d``), so every float but NaN comes back bit for bit.

    A one-channel reading is a plain message (``/name value``); a reading of several channels is
    what a VMC face tracker sends, ``/VMC/Ext/Blend/Val name value`` for each and
    ``/VMC/Ext/Blend/Apply``, in one bundle; so is a one-channel reading whose name is a VMC
    address (as a plain message it would be read as VMC).
    """
    device: OscDevice  # the adapter this twin feeds

    def __init__(self, device: OscDevice, sender: socket.socket, url: str) -> None:
        self.sender = sender
        super().__init__(device, url)

    @classmethod
    def from_url(cls, url: str, name: str, wire_info: Mapping[str, Any]) -> OscTwin:
        OscDevice.from_url(Url.parse(url), name)  # the logged URL must be a valid one
        return cls(OscDevice(name, "127.0.0.1", 0), socket.socket(socket.AF_INET, socket.SOCK_DGRAM), url)

    def _put(self, values: Mapping[str, float]) -> int:
        self.sender.sendto(_datagram(values), self.device.address)
        return 1

    def close(self) -> None:
        super().close()
        self.sender.close()


def _datagram(values: Mapping[str, float]) -> bytes:
    """One reading as OSC: a plain message for one channel, else a VMC bundle."""
    if len(values) == 1 and "/" + next(iter(values)) not in (BLEND_VALUE, BLEND_APPLY):
        [(name, value)] = values.items()
        return _message("/" + name, value).dgram
    bundle = OscBundleBuilder(IMMEDIATELY)
    for name, value in values.items():
        bundle.add_content(_message(BLEND_VALUE, name, value))
    bundle.add_content(_message(BLEND_APPLY))
    return bundle.build().dgram


def _message(address: str, *args: str | float) -> OscMessage:
    builder = OscMessageBuilder(address)
    for arg in args:
        kind = builder.ARG_TYPE_STRING if isinstance(arg, str) else builder.ARG_TYPE_DOUBLE
        builder.add_arg(arg if isinstance(arg, str) else float(arg), kind)
    return builder.build()


DEVICE, TWIN = OscDevice, OscTwin
