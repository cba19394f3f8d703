"""Serial devices (Arduino slider boxes, USB joysticks on a CDC port) read through pyserial.

URLs
----
``serial:///dev/ttyACM0?baudrate=115200&protocol=ascii``
    a port by path (``serial:/dev/ttyACM0`` and ``serial:COM3`` also work).
``serial:loop://?protocol=slip``, ``serial:socket://host:7777?protocol=cobs``, ...
    any pyserial URL handler (``serial_for_url``): write the pyserial URL right after ``serial:``
    and our options after it. Options this module does not know are handed on to the pyserial URL
    (``serial:loop://?protocol=cobs&logging=debug`` opens ``loop://?logging=debug``); with a plain
    path an unknown option is an error. (Our URL parser drops options without a value, so a
    pyserial option such as rfc2217's ``ign_set_control`` must be written ``ign_set_control=1``
    -- which rfc2217 accepts.)

Options: ``protocol=ascii|cobs|slip`` (default ascii); ``channels=a,b,c`` names the channels
(default ``ch0``, ``ch1``, ...); ``format=i16|f32`` (cobs and slip, default i16);
``timeout=0.03`` seconds a read waits (what bounds ``close()``); ``checksum=nmea`` (ascii only,
below); and the port settings ``baudrate`` (115200), ``bytesize``, ``parity``, ``stopbits``,
``xonxoff``, ``rtscts``, ``dsrdtr``, ``exclusive``. Any other option is refused (with a pyserial
URL handler, the handler's own options -- ``logging``, rfc2217's ``poll_modem`` ... -- are known
too and handed on).

The protocols (``ascii`` lines, ``cobs`` and ``slip`` frames) are ``devices.serial_wire``.

Reading
-------
The reader thread asks pyserial for what is waiting, or waits up to ``timeout`` (30 ms) for the
first byte, so ``close()`` is prompt. Samples from one read share the timestamp the base class
takes when the read returns. When the port goes away (pyserial raises ``SerialException``, an
``OSError``: a USB port unplugged, a pseudo-terminal whose master closed -- EIO, or "device reports
readiness to read but returned no data") the read raises ``DeviceLost`` and the base class
reopens the port with backoff; partial data of the lost connection is dropped.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping, Sequence
from typing import Any
from urllib.parse import urlencode

import serial
from serial.tools import list_ports

from devices.base import Device, DeviceError, DeviceLost, Found, Url
from devices.serial_wire import add_checksum, encode_reading, make_parser
from devices.simulated_serial import PtyJoystick
from devices.twin import Twin

TIMEOUT = 0.03          # seconds a read waits for the first byte
READ_MAX = 16384        # most bytes taken from the port in one read (one timestamp)

# -- the device --------------------------------------------------------------------------------

_PORT_OPTIONS: dict[str, Any] = {
    "baudrate": int, "bytesize": int, "parity": str.upper, "stopbits": float,
    "xonxoff": "bool", "rtscts": "bool", "dsrdtr": "bool", "exclusive": "bool",
}
_TRUE, _FALSE = {"1", "true", "yes", "on"}, {"0", "false", "no", "off"}
HANDLER_OPTIONS = frozenset({"logging", "ign_set_control", "poll_modem", "file", "color", "raw", "all",
                             "class", "n", "skip_busy"})
"""Options of pyserial's own URL handlers (loop, socket, rfc2217, spy, alt, hwgrep): with a
``serial:HANDLER://`` URL they are handed on to pyserial."""


class SerialDevice(Device):
    """Readings from a serial port (a path or any pyserial URL) in one of three protocols."""

    OPTIONS = frozenset({"protocol", "format", "channels", "timeout", "checksum", *_PORT_OPTIONS})

    @classmethod
    def unknown_option(cls, url: Url, key: str) -> str | None:
        if "://" in url.target and key in HANDLER_OPTIONS:
            return None
        return super().unknown_option(url, key)

    def __init__(self, name: str, port: str, *, protocol: str = "ascii",
                 channels: Sequence[str] | None = None, fmt: str = "i16", checksum: str = "none",
                 timeout: float = TIMEOUT, baudrate: int = 115200, **port_options: object) -> None:
        super().__init__(name)
        if channels is not None:
            channels = tuple(channels)
            if not channels or len(set(channels)) != len(channels) or not all(channels):
                raise DeviceError(f"serial {port!r}: channel names must be distinct and non-empty: {channels}")
        if protocol == "ascii" and fmt != "i16":
            raise DeviceError(f"serial {port!r}: format= applies to cobs and slip, not ascii")
        if not 0 < timeout <= 0.5:
            raise DeviceError(f"serial {port!r}: timeout must be in (0, 0.5] seconds, not {timeout}")
        try:
            self._parser = make_parser(protocol, channels, fmt, checksum)
        except ValueError as exc:
            raise DeviceError(f"serial {port!r}: {exc}") from None
        self.port_url = port
        self.protocol, self.channels, self.fmt, self.checksum = protocol, channels, fmt, checksum
        self._port_kwargs: dict[str, Any] = dict(port_options, baudrate=baudrate, timeout=timeout)
        try:  # check the URL handler and settings now, so _open only fails when hardware does
            serial.serial_for_url(port, do_not_open=True, **self._port_kwargs)
        except (ValueError, TypeError) as exc:
            raise DeviceError(f"serial {port!r}: {exc}") from None
        self._port: serial.SerialBase | None = None

    @classmethod
    def from_url(cls, url: Url, name: str) -> SerialDevice:
        options = dict(url.options)
        target = url.target
        if not target:
            raise DeviceError("serial URL: expected serial:///dev/PORT or serial:HANDLER://..., "
                              "e.g. serial:///dev/ttyACM0?protocol=ascii")
        cls.check_options(url)
        kwargs: dict[str, Any] = {}
        try:
            if "protocol" in options:
                kwargs["protocol"] = options.pop("protocol")
            if "checksum" in options:
                kwargs["checksum"] = options.pop("checksum")
            if "format" in options:
                kwargs["fmt"] = options.pop("format")
            if "channels" in options:
                kwargs["channels"] = [c.strip() for c in options.pop("channels").split(",")]
            if "timeout" in options:
                kwargs["timeout"] = float(options.pop("timeout"))
            for key, convert in _PORT_OPTIONS.items():
                if key in options:
                    kwargs[key] = _bool(options.pop(key)) if convert == "bool" else convert(options.pop(key))
        except ValueError as exc:
            raise DeviceError(f"serial URL {target!r}: {exc}") from None
        if options:  # a URL handler's own options (check_options let no other through)
            target += ("&" if "?" in target else "?") + urlencode(options)
        return cls(name, target, **kwargs)

    @property
    def port(self) -> serial.SerialBase | None:
        """The open pyserial port (None while closed): a loop:// port is written through it."""
        return self._port

    def _open(self) -> None:
        self._parser.reset()
        self._port = serial.serial_for_url(self.port_url, **self._port_kwargs)

    def _read(self) -> list[dict[str, float]]:
        port: Any = self._port  # open here; pyserial's stub leaves in_waiting off SerialBase
        try:
            waiting = port.in_waiting
            data = port.read(min(waiting, READ_MAX) if waiting else 1)
            if data and not waiting:
                waiting = port.in_waiting
                if waiting:
                    data += port.read(min(waiting, READ_MAX))
        except OSError as exc:  # serial.SerialException is an OSError
            raise DeviceLost(f"{self.port_url}: {exc}") from exc
        if not data:
            return []
        parser = self._parser
        readings = parser.feed(data)
        if parser.bad:
            self.counters.bad_frames += parser.bad
            parser.bad = 0
            if self.checksum != "none":
                self.counters.bad_checksums += parser.bad_checksums  # type: ignore[attr-defined]  # ascii's parser
                parser.bad_checksums = 0  # type: ignore[attr-defined]
        return readings

    def _close(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            with contextlib.suppress(Exception):  # a vanished port may fail to close: nothing to do
                port.close()


def _bool(text: str) -> bool:
    low = text.lower()
    if low in _TRUE:
        return True
    if low in _FALSE:
        return False
    raise ValueError(f"expected a yes/no value, not {text!r}")




class SerialTwin(Twin):
    """``serial://`` and ``sim://`` wires: a PtyJoystick sending nothing by itself (``rate=None``),
    a serial adapter reading its pseudo-terminal with the logged protocol, format and channel
    names, and logged readings written on it as the adapter parses them.

    ascii readings go as ``name=value`` pairs with ``repr`` floats, which parse back bit for bit
    (NaN and infinities excepted: the parser refuses them, so the adapter reports a bad frame);
    the line must stay within ``MAX_LINE`` bytes. cobs and slip frames carry the values in the
    adapter's channel order, as int16 (integers -32768..32767 only) or float32 (float32 values
    only): anything else comes back different or cannot be packed.
    """
    device: SerialDevice  # the adapter this twin feeds

    def __init__(self, device: SerialDevice, joystick: PtyJoystick, url: str) -> None:
        self.joystick = joystick
        super().__init__(device, url)

    @classmethod
    def from_url(cls, url: str, name: str, wire_info: Mapping[str, Any]) -> SerialTwin:
        options = Url.parse(url).options
        joystick = PtyJoystick(rate=None)  # only a carrier: the twin writes the wire bytes
        decoding = {k: v for k, v in options.items() if k in ("protocol", "format", "channels", "checksum")}
        try:
            device = SerialDevice.from_url(Url("serial", joystick.path, decoding), name)
        except DeviceError:
            joystick.close()
            raise
        return cls(device, joystick.start(), url)

    def _put(self, values: Mapping[str, float]) -> int:
        device = self.device
        if device.protocol == "ascii":
            line = ",".join(f"{k}={float(v)!r}" for k, v in values.items()).encode("ascii")
            data = add_checksum(line, device.checksum) + b"\n"
        else:
            names = device.channels or [f"ch{i}" for i in range(len(values))]
            if set(names) != set(values):
                raise ValueError(f"a {device.protocol} frame carries the channels {list(names)} in order")
            data = encode_reading([values[k] for k in names], device.protocol, device.fmt)
        if not self.joystick.write(data):
            raise ValueError(f"{len(data)} bytes do not fit the pseudo-terminal")
        return 1

    def close(self) -> None:
        super().close()
        self.joystick.close()


def discover() -> list[Found]:
    """The serial ports there are now (pyserial's list, with the USB vendor:product ids)."""
    return [Found("serial", f"serial://{p.device}", _serial_description(p))
            for p in sorted(list_ports.comports(), key=lambda p: p.device)]

def _serial_description(port: Any) -> str:
    usb = f"USB {port.vid:04x}:{port.pid:04x}" if port.vid is not None and port.pid is not None else None
    words = (port.manufacturer, port.product) if usb else (port.description,)
    return " ".join(dict.fromkeys(w for w in (*words, usb) if w and w != "n/a")) or "serial port"

DEVICE, TWIN = SerialDevice, SerialTwin
