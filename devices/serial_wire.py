"""The serial wire formats: ascii lines (with an optional NMEA check), COBS and SLIP frames.

What a serial controller sends, and how it is read back (``make_parser``) and written
(``encode_reading``, for the simulated joystick and the replay twin), byte for byte.

Protocols
---------
``ascii``: what an Arduino sketch ``Serial.println``-s. One reading per line, ended by CR, LF or
CRLF. Either numbers separated by commas, semicolons, spaces or tabs (``512,300,1023`` -> ``ch0``,
``ch1``, ``ch2``, or the names given by ``channels=``, in which case the count must match), or
``name=value`` / ``name:value`` pairs (``slider1=512 slider2=300``, ``a:1,b:2`` as Arduino's
Serial Plotter prints; with ``channels=`` every name must be one of them). Numbers are decimal
(``-12``, ``3.5``, ``1e3``); NaN and infinities are refused. A malformed line (text, a non-number,
a wrong count, mixed forms, a repeated name, a line over 4096 bytes) counts as one bad frame and
is skipped; blank lines are ignored; a line split across reads is joined.

Plain ascii cannot tell noise from data: a line cut short (``51`` of ``512``) or a digit flipped
on the wire is still a number. ``checksum=nmea`` makes every line carry the NMEA 0183 check:
``512,300*4A`` -- ``*`` and two hex digits, the XOR of every byte of the line before the ``*``
(a leading ``$`` is allowed, and left out of the XOR as in NMEA). A line without it, or whose
check differs, is a bad frame, and is also counted in ``counters.bad_checksums``. It catches every
single flipped bit and every cut line, but an 8-bit XOR misses two errors in the same bit
position: for a link that matters, ``cobs`` or ``slip`` with their CRC-16 is the safe choice.
An Arduino sketch: ``byte x = 0; for (char c : line) x ^= c;`` then print ``line``, ``'*'``
and ``x`` as two hex digits.

``cobs`` and ``slip``: binary frames for high rates. Every frame carries one reading::

    payload = N (1 byte, 1..255 channels)
              N values, little-endian: int16 (format=i16, 2N bytes) or float32 (format=f32, 4N)
    frame   = payload + CRC-16/CCITT-FALSE of the payload (2 bytes, big-endian)

and is then framed, either by COBS (consistent overhead byte stuffing: the frame holds no 0x00,
and 0x00 delimits frames) or by SLIP (RFC 1055: 0xC0 END delimits; 0xC0 and 0xDB inside the frame
are sent as 0xDB 0xDC and 0xDB 0xDD). The encoders here send a delimiter before *and* after each
frame (``00 <cobs> 00``, ``C0 <slip> C0``); the reader also takes frames with only the trailing
delimiter (Arduino PacketSerial style). Sending the leading one costs a byte and means that line
noise between two frames becomes its own short "frame" that fails its check, so the next real
frame is never lost with it. Empty frames (delimiter pairs) are ignored.

Resynchronisation is free: the reader splits the stream at delimiters, so after garbage it drops
bytes up to the next delimiter and goes on. A frame that fails -- bad COBS code (a block longer
than the frame), bad SLIP escape, bad CRC, N = 0, a length that is not 1 + 2N (or 1 + 4N) + 2, a
non-finite float, a count other than the ``channels=`` names, or more than 2048 bytes without a
delimiter -- counts as one bad frame in ``counters.bad_frames`` and yields nothing.

Why CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, not reflected, no final xor; check value 0x29B1
for ``b"123456789"``): two bytes are cheap at thousands of frames a second; it detects every
error burst up to 16 bits and has Hamming distance 4 far beyond our longest frame (1023 bytes), so
line noise that gets past the framing yields a wrong reading with odds of about 1 in 65,536 per
corrupted frame, rather than the 1 in 256 of an 8-bit sum; microcontrollers have it at hand (AVR
libc: start at 0xFFFF and feed ``_crc_xmodem_update``; in CRC libraries pick the variant whose
check value is 0x29B1, not the reflected "KERMIT" one); and Python computes it
in C with ``binascii.crc_hqx(data, 0xFFFF)``. Because it is not reflected and has no final xor,
the CRC of payload + CRC (big-endian) is 0, which is how the reader checks a frame in one call.

``encode_cobs_frame``, ``encode_slip_frame`` and ``encode_ascii_line`` produce exactly these wire
formats, for the simulated devices and the replay tool.
"""

from __future__ import annotations

import math
import re
import struct
from binascii import crc_hqx
from collections.abc import Mapping, Sequence

PROTOCOLS = ("ascii", "cobs", "slip")
FORMATS = {"i16": ("h", 2), "f32": ("f", 4)}
MAX_LINE = 4096         # longest ascii line
MAX_FRAME = 2048        # longest cobs/slip frame on the wire, delimiters excluded
CRC_INIT = 0xFFFF
CHECKSUMS = ("none", "nmea")

SLIP_END, SLIP_ESC, SLIP_ESC_END, SLIP_ESC_ESC = 0xC0, 0xDB, 0xDC, 0xDD
_END, _ESC = bytes([SLIP_END]), bytes([SLIP_ESC])
_ESC_END, _ESC_ESC = bytes([SLIP_ESC, SLIP_ESC_END]), bytes([SLIP_ESC, SLIP_ESC_ESC])


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data``."""
    return crc_hqx(data, CRC_INIT)


# -- encoders (the wire formats) ---------------------------------------------------------------

def encode_payload(values: Sequence[float], fmt: str = "i16") -> bytes:
    """Count byte, values, CRC: one reading before framing. i16 values are rounded to integers."""
    n = len(values)
    if not 1 <= n <= 255:
        raise ValueError(f"a frame carries 1 to 255 channels, not {n}")
    code, _ = _format(fmt)
    if code == "h":
        values = [round(float(v)) for v in values]
        if not all(-32768 <= v <= 32767 for v in values):
            raise ValueError(f"int16 frame: values out of range: {values}")
    body = struct.pack(f"<B{n}{code}", n, *values)
    return body + crc16(body).to_bytes(2, "big")


def cobs_encode(data: bytes) -> bytes:
    """COBS: ``data`` with every 0x00 removed, each block led by its length + 1 (0xFF: 254, no zero)."""
    out = bytearray()
    parts = bytes(data).split(b"\x00")
    last = len(parts) - 1
    for i, part in enumerate(parts):
        full = len(part) // 254
        for b in range(full):
            out.append(0xFF)
            out += part[b * 254:(b + 1) * 254]
        rest = part[full * 254:]
        if rest or i < last or not full:  # a final run of whole 0xFF blocks needs no closing code
            out.append(len(rest) + 1)
            out += rest
    return bytes(out)


def cobs_decode(data: bytes) -> bytes | None:
    """The bytes ``cobs_encode`` was given, or None when ``data`` is not valid COBS."""
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        code = data[i]
        if code == 0:
            return None
        end = i + code
        if end > n:
            return None
        out += data[i + 1:end]
        if code != 0xFF and end < n:
            out.append(0)
        i = end
    return bytes(out)


def slip_encode(data: bytes) -> bytes:
    """SLIP escaping (no delimiters): 0xDB -> 0xDB 0xDD, 0xC0 -> 0xDB 0xDC."""
    return bytes(data).replace(_ESC, _ESC_ESC).replace(_END, _ESC_END)


def slip_decode(data: bytes) -> bytes | None:
    """The bytes ``slip_encode`` was given, or None on a bad escape."""
    if SLIP_ESC not in data:
        return bytes(data)
    parts = bytes(data).split(_ESC)
    out = bytearray(parts[0])
    for part in parts[1:]:
        if not part:
            return None
        first = part[0]
        if first == SLIP_ESC_END:
            out.append(SLIP_END)
        elif first == SLIP_ESC_ESC:
            out.append(SLIP_ESC)
        else:
            return None
        out += part[1:]
    return bytes(out)


def encode_cobs_frame(values: Sequence[float], fmt: str = "i16") -> bytes:
    """One reading as a COBS frame on the wire: ``00 cobs(payload + crc) 00``."""
    return b"\x00" + cobs_encode(encode_payload(values, fmt)) + b"\x00"


def encode_slip_frame(values: Sequence[float], fmt: str = "i16") -> bytes:
    """One reading as a SLIP frame on the wire: ``C0 slip(payload + crc) C0``."""
    return _END + slip_encode(encode_payload(values, fmt)) + _END


def encode_ascii_line(values: Sequence[float] | Mapping[str, float], sep: str = ",",
                      end: str = "\r\n", checksum: str = "none") -> bytes:
    """One reading as an Arduino-style line: ``512,300`` or, from a dict, ``a=512,b=300``;
    with ``checksum="nmea"``, followed by ``*`` and the line's XOR in two hex digits."""
    if isinstance(values, Mapping):
        text = sep.join(f"{k}={_number(v)}" for k, v in values.items())
    else:
        text = sep.join(_number(v) for v in values)
    return add_checksum(text.encode("ascii"), checksum) + end.encode("ascii")


def nmea_checksum(data: bytes) -> int:
    """The XOR of every byte of ``data`` (the NMEA 0183 sentence check)."""
    x = 0
    for b in data:
        x ^= b
    return x


def add_checksum(line: bytes, checksum: str = "none") -> bytes:
    """``line`` with its ``*hh`` check appended when ``checksum`` is ``nmea``."""
    _check_checksum(checksum)
    return line + b"*%02X" % nmea_checksum(line) if checksum == "nmea" else line


def _check_checksum(checksum: str) -> None:
    if checksum not in CHECKSUMS:
        raise ValueError(f"checksum {checksum!r}: expected one of {', '.join(CHECKSUMS)}")


def _number(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else repr(float(v))


def _format(fmt: str) -> tuple[str, int]:
    try:
        return FORMATS[fmt]
    except KeyError:
        raise ValueError(f"format {fmt!r}: expected one of {sorted(FORMATS)}") from None


# -- parsers (bytes in, readings out) ----------------------------------------------------------

class _Splitter:
    """Splits a byte stream at a delimiter, joining chunks across reads and bounding their size.

    ``feed`` returns the readings of the complete chunks; a chunk ``_decode`` refuses (None)
    counts in ``bad``, which the owner reads and resets.
    """

    DELIMITER = b"\n"
    LIMIT = MAX_FRAME

    def __init__(self, names: Sequence[str] | None = None) -> None:
        self.names = tuple(names) if names else None
        self.bad = 0
        self._tail = b""
        self._skipping = False        # inside an overlong chunk, already counted
        self._default_names: dict[int, tuple[str, ...]] = {}

    def reset(self) -> None:
        """Forget a partial chunk (a new connection starts clean)."""
        self._tail, self._skipping = b"", False

    def feed(self, data: bytes) -> list[dict[str, float]]:
        data = self._normalise(data)
        delimiter = self.DELIMITER
        if delimiter not in data:
            if not self._skipping:
                self._tail += data
                if len(self._tail) > self.LIMIT:
                    self._overflow()
            return []
        chunks = data.split(delimiter)
        if self._skipping:
            chunks[0], self._skipping = b"", False
        else:
            chunks[0] = self._tail + chunks[0]
        self._tail = chunks.pop()
        out = []
        decode = self._decode
        for chunk in chunks:
            if chunk:
                reading = decode(chunk)
                if reading:
                    out.append(reading)
                elif reading is None:
                    self.bad += 1
        if len(self._tail) > self.LIMIT:
            self._overflow()
        return out

    def _overflow(self) -> None:
        self.bad += 1
        self._tail, self._skipping = b"", True

    def _normalise(self, data: bytes) -> bytes:
        return data

    def _decode(self, chunk: bytes) -> dict[str, float] | None:
        raise NotImplementedError

    def _names_for(self, n: int) -> tuple[str, ...] | None:
        if self.names is not None:
            return self.names if n == len(self.names) else None
        names = self._default_names.get(n)
        if names is None:
            names = self._default_names[n] = tuple(f"ch{i}" for i in range(n))
        return names


_HEX2 = re.compile(rb"[0-9A-Fa-f]{2}")
_SPACE_AROUND_PAIR = re.compile(r"\s*([=:])\s*")
_SEPARATORS = re.compile(r"[,;\s]+")


class AsciiParser(_Splitter):
    """Lines of numbers or name=value pairs (see the module docstring), each checked by its
    ``*hh`` when ``checksum`` is ``nmea`` (a failed check also counts in ``bad_checksums``)."""

    DELIMITER = b"\n"
    LIMIT = MAX_LINE

    def __init__(self, names: Sequence[str] | None = None, checksum: str = "none") -> None:
        super().__init__(names)
        _check_checksum(checksum)
        self.checksum = checksum
        self.bad_checksums = 0

    def _normalise(self, data: bytes) -> bytes:
        return data.replace(b"\r", b"\n") if b"\r" in data else data

    def _checked(self, chunk: bytes) -> bytes | None:
        """The line without its check, or None when the check is missing or wrong."""
        line = chunk.strip(b" \t")
        if not line:
            return line
        body, star, digits = line.rpartition(b"*")
        if body.startswith(b"$"):
            body = body[1:]
        if star and _HEX2.fullmatch(digits) and int(digits, 16) == nmea_checksum(body):
            return body
        self.bad_checksums += 1
        return None

    def _decode(self, chunk: bytes) -> dict[str, float] | None:
        if self.checksum == "nmea":
            checked = self._checked(chunk)
            if checked is None:
                return None
            chunk = checked
        try:
            line = chunk.decode("ascii").strip(" \t,;")
        except UnicodeDecodeError:
            return None
        if not line:
            return {}
        if "=" in line or ":" in line:
            return self._pairs(_SEPARATORS.split(_SPACE_AROUND_PAIR.sub(r"\1", line)))
        values = [_parse_number(token) for token in _SEPARATORS.split(line)]
        if None in values:
            return None
        names = self._names_for(len(values))
        return dict(zip(names, values)) if names else None  # type: ignore[arg-type]  # no None left

    def _pairs(self, tokens: list[str]) -> dict[str, float] | None:
        out = {}
        for token in tokens:
            name, sep, text = token.partition("=")
            if not sep:
                name, sep, text = token.partition(":")
            value = _parse_number(text) if sep else None
            if value is None or not name or name in out:
                return None
            if self.names is not None and name not in self.names:
                return None
            out[name] = value
        return out


def _parse_number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    if not math.isfinite(value) or "_" in text:
        return None
    return value


class _FrameParser(_Splitter):
    """Binary frames: unframe, check CRC and layout, name the values."""

    def __init__(self, names: Sequence[str] | None = None, fmt: str = "i16") -> None:
        super().__init__(names)
        self.fmt = fmt
        self._code, self._size = _format(fmt)
        self._structs: dict[int, struct.Struct] = {}

    def _unframe(self, chunk: bytes) -> bytes | None:
        raise NotImplementedError

    def _decode(self, chunk: bytes) -> dict[str, float] | None:
        frame = self._unframe(chunk)
        if frame is None or len(frame) < 4 or crc_hqx(frame, CRC_INIT) != 0:
            return None
        n = frame[0]
        if n == 0 or len(frame) != 3 + n * self._size:
            return None
        names = self._names_for(n)
        if names is None:
            return None
        unpack = self._structs.get(n)
        if unpack is None:
            unpack = self._structs[n] = struct.Struct(f"<{n}{self._code}")
        values = unpack.unpack_from(frame, 1)
        if self._code == "f":
            if not all(map(math.isfinite, values)):
                return None
            return dict(zip(names, values))
        return dict(zip(names, map(float, values)))


class CobsParser(_FrameParser):
    DELIMITER = b"\x00"

    def _unframe(self, chunk: bytes) -> bytes | None:
        return cobs_decode(chunk)


class SlipParser(_FrameParser):
    DELIMITER = _END

    def _unframe(self, chunk: bytes) -> bytes | None:
        return slip_decode(chunk)


def make_parser(protocol: str = "ascii", names: Sequence[str] | None = None,
                fmt: str = "i16", checksum: str = "none") -> _Splitter:
    """A parser for a protocol: ``feed(bytes) -> [readings]``, bad frames counted in ``bad``."""
    if protocol != "ascii" and checksum != "none":
        raise ValueError(f"checksum= applies to ascii lines; {protocol} frames carry a CRC-16 already")
    if protocol == "ascii":
        return AsciiParser(names, checksum)
    if protocol == "cobs":
        return CobsParser(names, fmt)
    if protocol == "slip":
        return SlipParser(names, fmt)
    raise ValueError(f"protocol {protocol!r}: expected one of {', '.join(PROTOCOLS)}")


STYLES = {"csv": ",", "space": " ", "pairs": ","}
"""ascii line styles: separator (pairs: ``name=value``)."""


def encode_reading(values: Sequence[float], protocol: str = "ascii", fmt: str = "i16", style: str = "csv",
                   names: Sequence[str] | None = None, checksum: str = "none") -> bytes:
    """One reading on the wire: a COBS or SLIP frame, or an ascii line in a style (with its
    ``*hh`` check when ``checksum`` is ``nmea``)."""
    if protocol == "cobs":
        return encode_cobs_frame(values, fmt)
    if protocol == "slip":
        return encode_slip_frame(values, fmt)
    if style == "pairs":
        names = names or [f"ch{i}" for i in range(len(values))]
        return encode_ascii_line(dict(zip(names, values)), STYLES["pairs"], checksum=checksum)
    return encode_ascii_line(values, STYLES[style], checksum=checksum)


__all__ = ["STYLES", "AsciiParser", "CobsParser", "SlipParser", "add_checksum", "cobs_decode", "cobs_encode",
           "crc16", "encode_ascii_line", "encode_cobs_frame", "encode_payload", "encode_reading",
           "encode_slip_frame", "make_parser", "nmea_checksum", "slip_decode", "slip_encode"]
