"""``sim://joystick``: a serial device with no hardware, for demos and for trying a mapping.

A ``SerialDevice`` that starts its own ``PtyJoystick`` (``devices.simulated_serial``) on a
pseudo-terminal and reads it through pyserial, as it would read an Arduino. Options:
``protocol``, ``rate`` (0 = as fast as possible), ``channels`` (a count, or names), ``format``
(i16/f32 for cobs and slip), ``style`` (csv, space or pairs for ascii), ``checksum`` (``nmea``),
``motion`` (``sines``, the default, or ``calibrate``: ``rest_then_sweep``, a hand doing what
``puppet calibrate`` asks, with ``rest`` seconds at rest first, default 4), ``seed`` (its noise).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from devices.base import DeviceError, Url
from devices.serial_port import SerialDevice, SerialTwin
from devices.simulated_serial import PtyJoystick, Signal, rest_then_sweep


def _joystick(url: Url, paced: bool) -> PtyJoystick:
    """The PtyJoystick a sim://joystick URL describes: sending at the URL's rate when ``paced``,
    else only when told (``rate=None``: a twin writes the logged readings itself)."""
    if url.target.strip("/") != "joystick":
        raise DeviceError(f"sim URL: expected sim://joystick?protocol=ascii&rate=200, got target {url.target!r}")
    SimulatedSerialDevice.check_options(url)
    options = url.options
    channels = options.get("channels", "6")
    try:
        rate = float(options.get("rate", "200"))
        names = [f"ch{i}" for i in range(int(channels))] if channels.isdigit() else channels.split(",")
        return PtyJoystick(options.get("protocol", "ascii"), (rate if rate > 0 else math.inf) if paced else None,
                           fmt=options.get("format", "i16"), style=options.get("style", "csv"), names=names,
                           checksum=options.get("checksum", "none"), signal=_motion(options, len(names)))
    except ValueError as exc:
        raise DeviceError(f"sim URL: {exc}") from None


def _motion(options: Mapping[str, str], channels: int) -> Signal | None:
    """The signal a sim URL's ``motion`` names (None: the joystick's default sines)."""
    motion = options.get("motion", "sines")
    if motion == "calibrate":
        rest = float(options.get("rest", "4"))
        if not 0 <= rest <= 600:
            raise ValueError(f"rest={rest:g}: expected seconds from 0 to 600")
        return rest_then_sweep(channels, rest, int(options.get("seed", "0")))
    if motion != "sines" or "rest" in options:
        raise ValueError(f"motion={motion}: expected sines, or calibrate (with rest=SECONDS)")
    return None


class SimulatedSerialDevice(SerialDevice):
    """``sim://joystick?...``: a SerialDevice reading a PtyJoystick it starts itself."""

    OPTIONS = frozenset({"protocol", "rate", "channels", "format", "style", "checksum", "motion", "rest", "seed"})

    def __init__(self, name: str, joystick: PtyJoystick, **serial_options: Any) -> None:
        super().__init__(name, joystick.path, protocol=joystick.protocol, fmt=joystick.fmt,
                         channels=joystick.names, checksum=joystick.checksum, **serial_options)
        self.joystick = joystick
        self._joystick_started = False

    @classmethod
    def from_url(cls, url: Url, name: str) -> SimulatedSerialDevice:
        return cls(name, _joystick(url, paced=True))

    def _open(self) -> None:
        """The first time: the pty, then the port, then the stream, so the port never opens in
        the middle of a line the joystick is sending (a cut first line would count as a bad
        frame). Later opens (after the joystick was unplugged and replugged) just reopen."""
        if self._joystick_started:
            super()._open()
            return
        if not self.joystick.plugged:
            self.joystick.replug()
        super()._open()
        self.joystick.start()
        self._joystick_started = True

    def restart_motion(self) -> None:
        """The simulated hand starts its motion over (``motion=calibrate``: rests, then sweeps):
        the live window asks it to when K starts a calibration, as it would ask a performer."""
        self.joystick.restart_motion()

    def close(self, timeout: float = 2.0) -> None:
        super().close(timeout)
        self.joystick.close()
        self._joystick_started = False


class SimTwin(SerialTwin):
    """``sim://joystick`` wires: the ``SimulatedSerialDevice`` itself, its joystick unpaced."""

    @classmethod
    def from_url(cls, url: str, name: str, wire_info: Mapping[str, Any]) -> SimTwin:
        joystick = _joystick(Url.parse(url), paced=False)
        return cls(SimulatedSerialDevice(name, joystick), joystick, url)


DEVICE, TWIN = SimulatedSerialDevice, SimTwin
