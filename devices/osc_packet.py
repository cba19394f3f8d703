"""OSC 1.0 datagrams read with bounds: every size checked before it is used, bundles nested at
most ``MAX_DEPTH`` deep, text strictly UTF-8.

The device reads what a sender on the network chose to send, so nothing in a datagram may
make the reader loop, recurse or allocate beyond the datagram itself. python-osc's parser is
built for trusted peers: a bundle element of negative size makes it loop forever, a non-UTF-8
address escapes as ``UnicodeDecodeError``, deep nesting as ``RecursionError``, and an unknown
type tag is logged for every message. Here each of those is an ``OscFormatError`` naming the
byte offset and what was found, and the caller drops the datagram.

``parse_datagram`` returns the messages in order as ``(address, arguments)``: integers (``i``,
``h``), floats (``f``, ``d``), strings (``s``, ``S``), bytes (``b``), booleans (``T``, ``F``),
``None`` (``N``, ``I``); time tags, characters, colours and MIDI messages as raw bytes. Array
brackets are accepted and flattened.
"""

from __future__ import annotations

import struct
from typing import Any

from devices.base import DeviceError

BUNDLE = b"#bundle\0"
MAX_DEPTH = 8
FIXED = {"i": (4, ">i"), "f": (4, ">f"), "d": (8, ">d"), "h": (8, ">q")}
RAW = {"t": 8, "c": 4, "r": 4, "m": 4}
CONSTANT = {"T": True, "F": False, "N": None, "I": None}

Message = tuple[str, list[Any]]


class OscFormatError(DeviceError, ValueError):
    """A datagram that is not well-formed OSC 1.0: where (byte offset) and what."""


def parse_datagram(datagram: bytes) -> list[Message]:
    """Every message in ``datagram`` (a message or a bundle), in order."""
    messages: list[Message] = []
    _element(bytes(datagram), 0, len(datagram), 0, messages)
    return messages


def _element(data: bytes, start: int, end: int, depth: int, out: list[Message]) -> None:
    """Parse the bundle or message that fills ``data[start:end]``."""
    if data.startswith(BUNDLE, start, end):
        _bundle(data, start, end, depth, out)
    else:
        out.append(_message(data, start, end))


def _bundle(data: bytes, start: int, end: int, depth: int, out: list[Message]) -> None:
    if depth >= MAX_DEPTH:
        raise OscFormatError(f"byte {start}: bundles nested more than {MAX_DEPTH} deep")
    at = start + 16  # "#bundle\0" and the time tag
    if at > end:
        raise OscFormatError(f"byte {start}: a bundle of {end - start} bytes, expected its 16-byte header")
    while at < end:
        if end - at < 4:
            raise OscFormatError(f"byte {at}: {end - at} stray bytes, expected an element size")
        (size,) = struct.unpack_from(">i", data, at)
        if size <= 0 or size % 4 or size > end - at - 4:
            raise OscFormatError(f"byte {at}: bundle element size {size}, expected a positive "
                                 f"multiple of 4 within the {end - at - 4} bytes left")
        _element(data, at + 4, at + 4 + size, depth + 1, out)
        at += 4 + size


def _message(data: bytes, start: int, end: int) -> Message:
    address, at = _string(data, start, end, "address")
    if not address.startswith("/"):
        raise OscFormatError(f"byte {start}: address {address[:40]!r}, expected one starting with '/'")
    if at >= end:
        return address, []  # OSC 1.0 allows a message with no type tag string
    tags, at = _string(data, at, end, "type tags")
    if not tags.startswith(","):
        raise OscFormatError(f"byte {at}: type tags {tags[:40]!r}, expected a string starting with ','")
    arguments = []
    for tag in tags[1:]:
        value, at = _argument(tag, data, at, end)
        if tag not in "[]":
            arguments.append(value)
    if at != end:
        raise OscFormatError(f"byte {at}: {end - at} bytes after the arguments the type tags name")
    return address, arguments


def _argument(tag: str, data: bytes, at: int, end: int) -> tuple[object, int]:
    """One argument of type ``tag`` at ``at``, and where the next one starts."""
    if tag in FIXED:
        size, code = FIXED[tag]
        _need(at, end, size, tag)
        return struct.unpack_from(code, data, at)[0], at + size
    if tag in "sS":
        return _string(data, at, end, "string argument")
    if tag == "b":
        _need(at, end, 4, tag)
        (size,) = struct.unpack_from(">i", data, at)
        if size < 0 or size > end - at - 4:
            raise OscFormatError(f"byte {at}: blob size {size}, expected 0 to {end - at - 4}")
        return data[at + 4:at + 4 + size], min(at + 4 + _padded(size), end)
    if tag in RAW:
        _need(at, end, RAW[tag], tag)
        return data[at:at + RAW[tag]], at + RAW[tag]
    if tag in CONSTANT or tag in "[]":
        return CONSTANT.get(tag), at
    raise OscFormatError(f"byte {at}: type tag {tag!r}, expected one of OSC 1.0's (ifdhsSbtcrmTFNI[])")


def _string(data: bytes, at: int, end: int, what: str) -> tuple[str, int]:
    """A NUL-terminated, 4-byte padded UTF-8 string at ``at``, and where the next field starts."""
    nul = data.find(b"\0", at, end)
    if nul < 0:
        raise OscFormatError(f"byte {at}: {what} without its terminating NUL")
    try:
        text = data[at:nul].decode("utf-8")
    except UnicodeDecodeError:
        raise OscFormatError(f"byte {at}: {what} {data[at:nul][:40]!r}, expected UTF-8 text") from None
    return text, min(at + _padded(nul - at + 1), end)


def _need(at: int, end: int, size: int, tag: str) -> None:
    if end - at < size:
        raise OscFormatError(f"byte {at}: {end - at} bytes left, expected {size} for a {tag!r} argument")


def _padded(size: int) -> int:
    return (size + 3) & ~3
