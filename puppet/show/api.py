"""The control API's messages: read, checked, and answered by a stage.

A client sends one JSON object per WebSocket text message (``api_schema.json`` documents them;
``check`` enforces the same rules by hand, so the server needs no schema library). Anything else
(not JSON, NaN or Infinity, a wrong type, an unknown key, a name too long) is an ``ApiError``
whose text is the reason the reply gives; the connection and the live loop go on.

What a message does is the stage's business (``puppet.show.stage``): the live session's, or a
playback's, which refuses what only a live session can do.
"""

from __future__ import annotations

import json
import math
from importlib import resources
from typing import Any

from puppet.errors import PuppetError

MAX_MESSAGE = 64 * 1024
"""The longest message a client may send, in bytes; the server closes a connection that sends a
longer one (WebSocket close code 1009, "message too big")."""
MAX_NAME = 64
MAX_CHANNELS = 256
MAX_ID = 2**53 - 1

TYPES = ("status", "subscribe", "unsubscribe", "set", "trigger", "record", "takes", "neutral")
KEYS = {"status": (), "subscribe": ("interval",), "unsubscribe": (), "set": ("channels", "device"),
        "trigger": ("name", "action"), "record": ("action",), "takes": (), "neutral": ()}
REQUIRED = {"set": ("channels",), "trigger": ("name",), "record": ("action",)}
TRIGGER_ACTIONS = ("press", "release", "fire")
RECORD_ACTIONS = ("start", "stop")


class ApiError(PuppetError, ValueError):
    """A message the API refuses; the text is the reason sent back."""


def schema() -> dict:
    """The JSON schema of a client's message (``api_schema.json``)."""
    return json.loads(resources.files("puppet.show").joinpath("api_schema.json").read_text("utf-8"))


def _refuse_constant(name: str) -> None:
    raise ApiError(f"{name} is not a number JSON allows")


def parse(text: str | bytes) -> dict[str, Any]:
    """One client message, checked (``check``); ApiError with the reason otherwise."""
    if isinstance(text, bytes):
        raise ApiError("send JSON as a text message, not binary")
    if len(text.encode("utf-8", "surrogatepass")) > MAX_MESSAGE:
        raise ApiError(f"message longer than {MAX_MESSAGE} bytes")
    try:
        message = json.loads(text, parse_constant=_refuse_constant)
    except ApiError:
        raise
    except (ValueError, RecursionError) as exc:
        raise ApiError(f"not JSON: {exc}") from None
    return check(message)


def check(message: Any) -> dict[str, Any]:
    """``message`` if it is one the schema allows; ApiError naming the first thing wrong."""
    if not isinstance(message, dict):
        raise ApiError(f"a message is a JSON object, got {type(message).__name__}")
    if "id" in message:
        _check_id(message["id"])
    kind = message.get("type")
    if kind not in TYPES:
        raise ApiError(f"type {kind!r:.80}: expected one of {', '.join(TYPES)}")
    allowed = {"id", "type", *KEYS[kind]}
    for key in message:
        if key not in allowed:
            raise ApiError(f"{kind}: unknown key {key!r:.80} (it takes {', '.join(KEYS[kind]) or 'nothing more'})")
    for key in REQUIRED.get(kind, ()):
        if key not in message:
            raise ApiError(f"{kind}: {key!r} is required")
    check_fields = _FIELD_CHECKS.get(kind)
    if check_fields is not None:
        check_fields(message)
    return message


def _check_id(value: Any) -> None:
    if isinstance(value, str) and len(value) <= MAX_NAME:
        return
    if _number(value) and float(value).is_integer() and abs(value) <= MAX_ID:  # JSON's 1.0 is an integer
        return
    raise ApiError(f"id: an integer or a string of at most {MAX_NAME} characters, got {value!r:.80}")


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _name(value: Any) -> bool:
    return isinstance(value, str) and 0 < len(value) <= MAX_NAME


def _check_subscribe(message: dict) -> None:
    interval = message.get("interval", 0.5)
    if not _number(interval) or not 0.05 <= interval <= 60:
        raise ApiError(f"subscribe: interval is seconds from 0.05 to 60, got {interval!r:.80}")


def _check_set(message: dict) -> None:
    channels = message["channels"]
    if not isinstance(channels, dict) or not 0 < len(channels) <= MAX_CHANNELS:
        raise ApiError(f"set: channels is an object of 1-{MAX_CHANNELS} channel: number pairs")
    for name, value in channels.items():
        if not _name(name):
            raise ApiError(f"set: channel names are 1-{MAX_NAME} characters, got {name!r:.80}")
        if not _number(value):
            raise ApiError(f"set: channel {name!r} needs a finite number, got {value!r:.80}")
    if "device" in message and not _name(message["device"]):
        raise ApiError(f"set: device is a name of 1-{MAX_NAME} characters, got {message['device']!r:.80}")


def _check_trigger(message: dict) -> None:
    if not _name(message["name"]):
        raise ApiError(f"trigger: name is 1-{MAX_NAME} characters, got {message['name']!r:.80}")
    if message.get("action", "fire") not in TRIGGER_ACTIONS:
        raise ApiError(f"trigger: action {message['action']!r:.80}: expected one of {', '.join(TRIGGER_ACTIONS)}")


def _check_record(message: dict) -> None:
    if message["action"] not in RECORD_ACTIONS:
        raise ApiError(f"record: action {message['action']!r:.80}: expected one of {', '.join(RECORD_ACTIONS)}")


_FIELD_CHECKS = {"subscribe": _check_subscribe, "set": _check_set, "trigger": _check_trigger, "record": _check_record}
"""The checks of each type's own fields (the types with none have none)."""
