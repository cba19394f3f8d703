"""CAN input devices (CAN joysticks, control panels on a CAN bus) read through python-can.

URLs (scheme ``can``): ``can://<interface>/<channel>?option=value&...``, any python-can interface
by name:

- ``can://virtual/ch0``: python-can's in-process virtual bus (tests, demos, ``simulated_can``);
- ``can://socketcan/can0?bitrate=500000``; ``can://pcan/PCAN_USBBUS1?bitrate=250000``;
  ``can://slcan/%2Fdev%2FttyACM0?bitrate=500000`` (a channel with slashes is url-encoded);
- ``can://virtual`` (no channel): the interface's default channel.

Options that are ours (every other option goes to ``can.Bus`` as a keyword, its value cast by
python-can's ``cast_from_string``: ``bitrate=500000`` -> int, ``fd=true`` -> bool):

- ``dbc=path/to/file.dbc``: the signals of every message in a DBC file (loaded by cantools);
- ``signals=NAME:ID:START:LENGTH[:ORDER[:SIGN[:SCALE[:OFFSET]]]];...``: signals by hand (see
  ``CanSignal.parse``; ORDER ``le``/``intel`` or ``be``/``motorola``, SIGN ``s`` or ``u``);
  the same can come from a mapping as a list of dicts (``CanDevice(signals=...)``);
- ``decoder=auto|own|cantools``: who decodes DBC signals. ``own`` is ``SignalDecoder`` below
  (a shift and a mask per signal, tested equal to cantools); ``cantools`` is
  ``Message.decode``, which also knows multiplexed and IEEE-float signals; ``auto`` (default)
  takes ``own`` unless the DBC has such signals;
- ``filter=1``: install acceptance filters for the signals' ids on the bus (in the kernel or the
  adapter where the interface can), so other traffic never reaches Python;
- ``timeout_ms=N``: how long one read waits (default 20 ms).

What a frame becomes: one reading whose channels are the frame's signals, named by signal name
(a name two messages share becomes ``Message.Signal`` for both, in a DBC). Frames with an id that
no signal uses are ignored and counted in ``ignored_frames`` (an attribute, not a bad frame: a bus
carries other nodes' traffic; with ``filter=1`` they are mostly never seen). Remote frames are
ignored the same way. A frame too short for its signals (short DLC) and error frames count in
``counters.bad_frames`` (a short frame's reason goes to ``counters.last_error``). 11-bit and 29-bit ids with the same number are not told apart.

A bus that fails (python-can raises ``CanOperationError``, e.g. the adapter was unplugged, or the
bus was shut down) makes the device LOST; it reopens with backoff. python-can's virtual bus has no
notion of a cable: nothing can unplug it, and frames sent while no receiver is connected are
simply not delivered. The nearest thing, used by the tests, is shutting the bus object down under
the device (``device.bus.shutdown()``).
"""

from __future__ import annotations

import os
import tempfile
import uuid
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote

from devices.base import Device, DeviceError, DeviceLost, Found, Url
from devices.twin import Twin

try:
    import can
except ImportError:  # the backend says what to install when it is used
    can = None  # type: ignore[assignment]

_OURS = {"dbc", "signals", "decoder", "filter", "timeout_ms"}
BUS_OPTIONS = frozenset({
    "app_name", "bitrate", "can_filters", "can_termination", "data_bitrate", "device", "device_id", "fd",
    "fd_bitrate", "frame_type", "hop_limit", "host", "ignore_rx_error_frames", "listen_only", "local_loopback",
    "log_errors", "monitor", "operation_mode", "poll_interval", "port", "preserve_timestamps", "protocol",
    "receive_own_messages", "rtscts", "rx_queue_size", "serial", "sjw_abr", "sjw_dbr", "sleep_after_open",
    "state", "tcp_tune", "timing", "tseg1_abr", "tseg1_dbr", "tseg2_abr", "tseg2_dbr", "ttyBaudrate",
    "tty_baudrate", "baudrate"})
"""The keyword arguments python-can's interfaces take (gathered from their constructors), which a
URL hands on to ``can.Bus``; any other option is a typo, refused."""
_ORDERS = {"le": "little_endian", "intel": "little_endian", "little": "little_endian",
           "little_endian": "little_endian", "be": "big_endian", "motorola": "big_endian",
           "big": "big_endian", "big_endian": "big_endian"}


class BadFrame(DeviceError, ValueError):
    """A frame with a known id that cannot carry its signals (too short)."""


@dataclass(frozen=True)
class CanSignal:
    """A signal in a CAN frame, numbered as in a DBC file.

    ``start`` is DBC's start bit: bit ``8 * byte + bit`` with bit 0 the least significant bit of a
    byte. For ``little_endian`` (Intel) signals it is the signal's least significant bit, and the
    signal runs upward; for ``big_endian`` (Motorola) it is the signal's most significant bit, and
    the signal runs toward bit 0 of that byte, then on from bit 7 of the next byte (the DBC
    "sawtooth"). The value is ``raw * scale + offset``, raw sign-extended when ``signed``.
    """

    name: str
    frame_id: int
    start: int
    length: int
    byte_order: str = "little_endian"
    signed: bool = False
    scale: float = 1
    offset: float = 0

    def __post_init__(self) -> None:
        if self.byte_order not in ("little_endian", "big_endian"):
            raise ValueError(f"CAN signal {self.name!r}: byte order {self.byte_order!r} "
                             "(little_endian or big_endian)")
        if self.length < 1 or self.start < 0 or self.frame_id < 0:
            raise ValueError(f"CAN signal {self.name!r}: needs length >= 1, start >= 0, id >= 0")
        if self.byte_order == "little_endian" and (self.start + self.length > 512):
            raise ValueError(f"CAN signal {self.name!r}: runs past 64 bytes")
        if self.byte_order == "big_endian" and self._msb_position() + self.length > 512:
            raise ValueError(f"CAN signal {self.name!r}: runs past 64 bytes")

    def _msb_position(self) -> int:
        """The most significant bit's position counted from the first bit on the wire (byte 0's
        bit 7 is 0): where a Motorola signal starts in the frame read as one big-endian integer."""
        return (self.start // 8) * 8 + 7 - self.start % 8

    @property
    def min_bytes(self) -> int:
        """How many data bytes a frame needs to carry this signal."""
        if self.byte_order == "little_endian":
            return (self.start + self.length - 1) // 8 + 1
        return (self._msb_position() + self.length - 1) // 8 + 1

    @classmethod
    def parse(cls, text: str) -> CanSignal:
        """``NAME:ID:START:LENGTH[:ORDER[:SIGN[:SCALE[:OFFSET]]]]``, e.g. ``X:0x100:0:16:le:s:0.001``."""
        parts = [p.strip() for p in text.strip().split(":")]
        if not 4 <= len(parts) <= 8 or not parts[0]:
            raise ValueError(f"CAN signal {text!r}: expected NAME:ID:START:LENGTH[:ORDER[:SIGN[:SCALE[:OFFSET]]]]")
        try:
            frame_id, start, length = (int(p, 0) for p in parts[1:4])
        except ValueError:
            raise ValueError(f"CAN signal {text!r}: id, start and length are integers") from None
        order = _ORDERS.get(parts[4].lower() if len(parts) > 4 else "le")
        if order is None:
            raise ValueError(f"CAN signal {text!r}: byte order {parts[4]!r} (le/intel or be/motorola)")
        sign = parts[5].lower() if len(parts) > 5 else "u"
        if sign not in ("s", "u", "signed", "unsigned"):
            raise ValueError(f"CAN signal {text!r}: sign {parts[5]!r} (s or u)")
        try:
            scale = _number(parts[6]) if len(parts) > 6 else 1
            offset = _number(parts[7]) if len(parts) > 7 else 0
        except ValueError:
            raise ValueError(f"CAN signal {text!r}: scale and offset are numbers") from None
        return cls(parts[0], frame_id, start, length, order, sign.startswith("s"), scale, offset)

    @classmethod
    def from_cantools(cls, signal: Any, frame_id: int, name: str | None = None) -> CanSignal:
        """The same signal as a cantools ``Signal`` (plain integer signals only)."""
        if signal.is_float or signal.multiplexer_ids or signal.is_multiplexer:
            raise ValueError(f"CAN signal {signal.name!r}: float or multiplexed signals need cantools")
        return cls(name or signal.name, frame_id, signal.start, signal.length, signal.byte_order,
                   signal.is_signed, signal.scale, signal.offset)


def _number(text: str) -> float:
    value = float(text)
    return int(value) if value.is_integer() and "." not in text and "e" not in text.lower() else value


class SignalDecoder:
    """Our decoder for CAN signals: per frame id, one integer of the data per byte order, then a
    shift, a mask, a sign extension and ``raw * scale + offset`` per signal. A frame must carry at
    least the bytes its signals reach, and at least ``lengths[id]`` bytes where given (a DBC
    message's declared length, as cantools asks)."""

    def __init__(self, signals: Iterable[CanSignal], lengths: Mapping[int, int] | None = None) -> None:
        by_id: dict[int, list[CanSignal]] = {}
        for s in signals:
            by_id.setdefault(s.frame_id, []).append(s)
        self.signals = [s for group in by_id.values() for s in group]
        self._plans: dict[int, tuple[int, bool, bool, list[tuple[Any, ...]]]] = {}
        for frame_id, group in by_id.items():
            nbytes = max([s.min_bytes for s in group] + [(lengths or {}).get(frame_id, 0)])
            plan = []
            for s in group:
                big = s.byte_order == "big_endian"
                shift = 8 * nbytes - (s._msb_position() + s.length) if big else s.start
                identity = s.scale == 1 and s.offset == 0
                plan.append((s.name, big, shift, (1 << s.length) - 1,
                             (1 << (s.length - 1)) if s.signed else 0, identity, s.scale, s.offset))
            self._plans[frame_id] = (nbytes, any(not p[1] for p in plan), any(p[1] for p in plan), plan)

    @property
    def frame_ids(self) -> list[int]:
        return list(self._plans)

    def decode(self, frame_id: int, data: bytes) -> dict[str, float] | None:
        """The signals of one frame, or None for an id no signal uses; ``BadFrame`` when short."""
        entry = self._plans.get(frame_id)
        if entry is None:
            return None
        nbytes, any_le, any_be, plan = entry
        if len(data) < nbytes:
            raise BadFrame(f"frame 0x{frame_id:x}: {len(data)} data bytes, its signals need {nbytes}")
        data = bytes(data[:nbytes])
        le = int.from_bytes(data, "little") if any_le else 0
        be = int.from_bytes(data, "big") if any_be else 0
        out = {}
        for name, big, shift, mask, sign, identity, scale, offset in plan:
            v = ((be if big else le) >> shift) & mask
            if sign and v & sign:
                v -= sign << 1
            out[name] = float(v) if identity else float(v * scale + offset)
        return out


    def encode(self, values: Mapping[str, float]) -> tuple[int, bytes]:
        """The frame (id, data) that ``decode`` turns back into ``values``, which must hold exactly
        one frame id's signals: each raw value is the integer nearest ``(value - offset) / scale``,
        clamped to the signal's bits, so a value no raw value decodes to exactly comes back
        different (the caller checks). For replaying logged readings (``simulated_can.CanTwin``)."""
        for frame_id, (nbytes, _, _, plan) in self._plans.items():
            if {p[0] for p in plan} == set(values):
                break
        else:
            raise ValueError(f"no frame carries exactly the signals {sorted(values)}")
        le = be = 0
        for name, big, shift, mask, sign, identity, scale, offset in plan:
            value = values[name]
            raw = round(value) if identity else round((value - offset) / scale)
            raw = max(-sign, min(raw, sign - 1)) if sign else max(0, min(raw, mask))
            if big:
                be |= (raw & mask) << shift
            else:
                le |= (raw & mask) << shift
        data = bytes(a | b for a, b in zip(le.to_bytes(nbytes, "little"), be.to_bytes(nbytes, "big")))
        return frame_id, data


class CantoolsDecoder:
    """DBC messages decoded by cantools itself (multiplexed and float signals included)."""

    def __init__(self, database: Any, names: Mapping[tuple[str, str], str]) -> None:
        self._messages = {m.frame_id: m for m in database.messages if m.signals}
        self._names = names
        self.frame_ids = list(self._messages)

    def decode(self, frame_id: int, data: bytes) -> dict[str, float] | None:
        message = self._messages.get(frame_id)
        if message is None:
            return None
        try:
            values = message.decode(bytes(data), decode_choices=False, scaling=True)
        except Exception as exc:  # cantools' DecodeError and friends: a frame it cannot read
            raise BadFrame(f"frame 0x{frame_id:x}: {exc}") from None
        rename = self._names
        return {rename.get((message.name, k), k): float(v) for k, v in values.items()}

    def encode(self, values: Mapping[str, float]) -> tuple[int, bytes]:
        """The frame (id, data) of the message whose signals ``values`` names (all of them, or the
        ones a multiplexer value selects), encoded by cantools: ``decode``'s inverse."""
        for message in self._messages.values():
            signals = {self._names.get((message.name, s.name), s.name): s.name for s in message.signals}
            if set(values) <= set(signals):
                try:
                    data = message.encode({signals[k]: v for k, v in values.items()}, scaling=True,
                                          strict=False)
                except Exception as exc:  # cantools' EncodeError and friends: values it cannot pack
                    raise ValueError(f"message {message.name}: {exc}") from None
                return message.frame_id, data
        raise ValueError(f"no message carries the signals {sorted(values)}")


def load_dbc(path: str, decoder: str = "auto") -> SignalDecoder | CantoolsDecoder:
    """A decoder for every message of a DBC file (``decoder``: auto, own or cantools)."""
    import cantools

    database: Any = cantools.database.load_file(path)  # a DBC file loads as a CAN database
    counts: dict[str, int] = {}
    for m in database.messages:
        for s in m.signals:
            counts[s.name] = counts.get(s.name, 0) + 1
    names = {(m.name, s.name): (f"{m.name}.{s.name}" if counts[s.name] > 1 else s.name)
             for m in database.messages for s in m.signals}
    if decoder in ("auto", "own"):
        try:
            return SignalDecoder((CanSignal.from_cantools(s, m.frame_id, names[m.name, s.name])
                                  for m in database.messages for s in m.signals),
                                 {m.frame_id: m.length for m in database.messages})
        except ValueError:
            if decoder == "own":
                raise
    return CantoolsDecoder(database, names)


class CanDevice(Device):
    """A CAN bus read through python-can; each frame with known signals becomes one reading."""

    BATCH = 64  # most frames taken in one _read
    OPTIONS = frozenset(_OURS) | BUS_OPTIONS

    def __init__(self, name: str, interface: str, channel: str | None = None, *,
                 signals: Sequence[CanSignal | Mapping[str, Any] | str] | None = None,
                 dbc: str | None = None, decoder: str = "auto", filter: bool = False,
                 timeout_ms: int = 20, bus_kwargs: Mapping[str, Any] | None = None) -> None:
        super().__init__(name)
        if can is None:
            raise DeviceError(f"{name}: CAN devices need python-can (pip install python-can)")
        if interface not in can.interfaces.VALID_INTERFACES:
            raise DeviceError(f"{name}: unknown python-can interface {interface!r}; known: "
                              f"{sorted(can.interfaces.VALID_INTERFACES)}")
        if (signals is None) == (dbc is None):
            raise DeviceError(f"{name}: a CAN device needs its signals: dbc=FILE or signals=... (one of them)")
        if decoder not in ("auto", "own", "cantools"):
            raise DeviceError(f"{name}: decoder {decoder!r} (auto, own or cantools)")
        if not 1 <= timeout_ms <= 1000:
            raise DeviceError(f"{name}: timeout_ms {timeout_ms} (expected 1..1000)")
        self._dbc_text: str | None = None
        try:
            if dbc is not None:
                with open(dbc, encoding="latin-1", newline="") as f:  # any bytes, kept exactly
                    self._dbc_text = f.read()
                self.decoder: SignalDecoder | CantoolsDecoder = load_dbc(dbc, decoder)
            else:
                self.decoder = SignalDecoder(_signal(s) for s in signals)  # type: ignore[union-attr]
        except (OSError, ValueError, TypeError) as exc:
            raise DeviceError(f"{name}: {exc}") from None
        except Exception as exc:  # cantools' parse errors
            raise DeviceError(f"{name}: cannot read DBC file {dbc!r}: {exc}") from None
        if not self.decoder.frame_ids:
            raise DeviceError(f"{name}: no signals to read")
        self.interface, self.channel = interface, channel
        self.filter, self.timeout = filter, timeout_ms / 1000.0
        self.bus_kwargs = dict(bus_kwargs or {})
        self.bus: Any = None
        self.ignored_frames = 0

    @classmethod
    def from_url(cls, url: Url, name: str, *,
                 signals: Sequence[CanSignal | Mapping[str, Any] | str] | None = None) -> CanDevice:
        text = f"{url.scheme}://{url.target}"
        cls.check_options(url)
        interface, _, channel = url.target.partition("/")
        if not interface:
            raise DeviceError(f"device URL {text!r}: expected can://<interface>/<channel>, e.g. can://socketcan/can0")
        o = dict(url.options)
        if "signals" in o:
            try:
                signals = [CanSignal.parse(s) for s in o.pop("signals").split(";") if s.strip()]
            except ValueError as exc:
                raise DeviceError(f"device URL {text!r}: {exc}") from None
        try:
            timeout_ms = int(o.pop("timeout_ms", "20"))
        except ValueError:
            raise DeviceError(f"device URL {text!r}: timeout_ms must be an integer") from None
        if can is None:
            raise DeviceError(f"{name}: CAN devices need python-can (pip install python-can)")
        dbc = o.pop("dbc", None)
        decoder = o.pop("decoder", "auto")
        filt = o.pop("filter", "0").lower() in ("1", "true", "yes", "on")
        bus_kwargs = {k: can.util.cast_from_string(v) for k, v in o.items()}
        return cls(name, interface, unquote(channel) or None, signals=signals, dbc=dbc, decoder=decoder,
                   filter=filt, timeout_ms=timeout_ms, bus_kwargs=bus_kwargs)

    def wire_info(self) -> dict[str, Any]:
        """What decodes the frames, so a take decodes as recorded later: the DBC file's text (even
        after the file changed or moved), or the hand-given signals (they may come from a
        mapping, not the URL)."""
        if self._dbc_text is not None:
            return {"dbc": self._dbc_text}
        return {"signals": [asdict(s) for s in self.decoder.signals]}  # type: ignore[union-attr]  # no DBC

    # -- Device ------------------------------------------------------------------------------

    def _open(self) -> None:
        kwargs = dict(self.bus_kwargs)
        if self.channel is not None:
            kwargs["channel"] = self.channel
        if self.filter:
            kwargs["can_filters"] = [{"can_id": i, "can_mask": 0x1FFFFFFF if i > 0x7FF else 0x7FF,
                                      "extended": i > 0x7FF} for i in self.decoder.frame_ids]
        try:
            self.bus = can.Bus(interface=self.interface, **kwargs)
        except (OSError, can.CanError, ValueError, TypeError, ImportError) as exc:
            raise OSError(f"{self.name}: cannot open {self.interface} bus {self.channel!r}: {exc}") from None

    def _read(self) -> list[dict[str, float]]:
        bus = self.bus
        try:
            msg = bus.recv(self.timeout)
        except can.CanError as exc:
            raise DeviceLost(f"{self.name}: {exc}") from None
        out = []
        decode = self.decoder.decode
        taken = 0
        while msg is not None:
            taken += 1
            if msg.is_error_frame:
                self.counters.bad_frames += 1
            elif msg.is_remote_frame:
                self.ignored_frames += 1
            else:
                try:
                    values = decode(msg.arbitration_id, msg.data)
                except BadFrame as exc:
                    self.counters.bad_frames += 1
                    self.counters.last_error = str(exc)
                else:
                    if values is None:
                        self.ignored_frames += 1
                    else:
                        out.append(values)
            if taken >= self.BATCH:
                break
            try:
                msg = bus.recv(0.0)  # what has come already
            except can.CanError as exc:
                if out:
                    break  # hand over what was read; the next read reports the loss
                raise DeviceLost(f"{self.name}: {exc}") from None
        return out

    def _close(self) -> None:
        bus, self.bus = self.bus, None
        if bus is not None:
            try:
                bus.shutdown()
            except Exception:
                pass


def _signal(s: CanSignal | Mapping[str, Any] | str) -> CanSignal:
    if isinstance(s, CanSignal):
        return s
    if isinstance(s, str):
        return CanSignal.parse(s)
    d = dict(s)
    if "id" in d:
        d["frame_id"] = d.pop("id")
    if isinstance(d.get("frame_id"), str):
        d["frame_id"] = int(d["frame_id"], 0)
    if "byte_order" in d:
        order = _ORDERS.get(str(d["byte_order"]).lower())
        if order is None:
            raise ValueError(f"CAN signal {d.get('name')!r}: byte order {d['byte_order']!r}")
        d["byte_order"] = order
    return CanSignal(**d)


class CanTwin(Twin):
    """``can://`` wires: a ``CanDevice`` with the logged URL's options (signals, decoder, filter,
    ...) on a fresh python-can ``virtual`` channel of its own, and a sender on that channel; a
    logged reading goes back as the frame its decoder's ``encode`` packs. The decoder comes from
    ``wire_info`` when the take kept it (the DBC text, or the hand-given signals), else from the
    URL (its ``signals=``, or its ``dbc=`` file as it is now).

    Values go through each signal's integer raw value (``raw * scale + offset``), so only values
    the decoder produces come back exactly; float signals (cantools) carry their float.
    """
    device: CanDevice  # the adapter this twin feeds

    def __init__(self, device: CanDevice, sender: Any, url: str) -> None:
        self.sender = sender
        super().__init__(device, url)

    @classmethod
    def from_url(cls, url: str, name: str, wire_info: Mapping[str, Any]) -> CanTwin:
        parsed = Url.parse(url)
        channel = f"twin-{uuid.uuid4().hex}"
        options = dict(parsed.options)
        if "dbc" in wire_info:
            device = _with_dbc_text(Url("can", f"virtual/{channel}", options), name, wire_info["dbc"])
        else:
            device = CanDevice.from_url(Url("can", f"virtual/{channel}", options), name,
                                        signals=wire_info.get("signals"))
        return cls(device, can.Bus(interface="virtual", channel=channel), url)

    def _put(self, values: Mapping[str, float]) -> int:
        frame_id, data = self.device.decoder.encode(values)
        self.sender.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=frame_id > 0x7FF))
        return 1

    def close(self) -> None:
        super().close()
        self.sender.shutdown()


def _with_dbc_text(url: Url, name: str, text: str) -> CanDevice:
    """A CanDevice whose ``dbc=`` is ``text``, through a temporary file (CanDevice reads a path)."""
    fd, path = tempfile.mkstemp(suffix=".dbc")
    try:
        with os.fdopen(fd, "w", encoding="latin-1", newline="") as f:
            f.write(text)
        return CanDevice.from_url(Url(url.scheme, url.target, {**url.options, "dbc": path}), name)
    finally:
        os.unlink(path)


def discover(net: Path = Path("/sys/class/net")) -> list[Found]:
    """SocketCAN interfaces that are up (``net``: the kernel's network interface folder)."""
    if not net.is_dir():
        raise OSError("no SocketCAN here (Linux only); open a CAN adapter by URL, e.g. can://pcan/PCAN_USBBUS1")
    found = []
    for interface in sorted(net.iterdir()):
        if _read(interface / "type") != CAN_TYPE:
            continue
        flags = int(_read(interface / "flags") or "0", 16)
        if flags & IFF_UP:
            bitrate = _read(interface / "can_bittiming" / "bitrate")
            found.append(Found("can", f"can://socketcan/{interface.name}",
                               f"SocketCAN, up{f', {int(bitrate):,} bit/s' if bitrate else ''}"))
    return found

CAN_TYPE = "280"
"""ARPHRD_CAN: a network interface of this type is a CAN bus."""
IFF_UP = 0x1


def _read(path: Path) -> str | None:
    try:
        return path.read_text().strip()
    except OSError:
        return None

DEVICE, TWIN = CanDevice, CanTwin
