"""What the control API's messages act on: a live session, or a take being played.

The server (``puppet.show.server``) answers ``status`` from the newest status the loop published,
and hands every other message to its stage. ``set`` only pushes a reading into the mapping's
``api://`` device, which is safe from any thread; the rest (triggers, takes, the neutral key)
change the session, so the server queues them and the live loop runs them between frames
(``ShowServer.service``). A playback has no session: it refuses them with the reason.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from devices.api_device import ApiDevice
from puppet.io.takes import META_NAME, TakeError, open_take
from puppet.show.api import ApiError


class Stage:
    """A playback's stage: nothing to drive, so every message but ``status`` is refused."""

    live = False

    def set(self, channels: dict[str, float], device: str | None) -> dict:
        raise ApiError("set: this is a playback; channels are set on `puppet live --serve`")

    def run(self, message: dict) -> dict:
        """Act on a checked message (not ``status``/``set``/subscriptions), on the loop thread."""
        raise ApiError(f"{message['type']}: this is a playback; there is no live session to drive")


class LiveStage(Stage):
    """The live session's stage. ``start_take``/``stop_take`` default to the session's own; a
    window passes its own, so that a take started from the API shows in its cockpit too."""

    live = True

    def __init__(self, session: Any, *, start_take: Callable[[], Path] | None = None,
                 stop_take: Callable[[], Path] | None = None) -> None:
        self.session = session
        self.start_take = start_take or session.start_recording
        self.stop_take = stop_take or session.stop_recording
        self.api_devices = {name: d for name, d in session.devices.items() if isinstance(d, ApiDevice)}

    def set(self, channels: dict[str, float], device: str | None) -> dict:
        if not self.api_devices:
            raise ApiError('set: the mapping has no api:// device; add one under devices: '
                           '`api: {url: "api://"}`, and route its channels')
        if device is None:
            if len(self.api_devices) > 1:
                raise ApiError(f"set: the mapping has several api:// devices; name one in device "
                               f"({', '.join(self.api_devices)})")
            device = next(iter(self.api_devices))
        if device not in self.api_devices:
            raise ApiError(f"set: no api:// device {device!r}; the mapping has {', '.join(self.api_devices)}")
        try:
            self.api_devices[device].push(channels)
        except ValueError as exc:
            raise ApiError(f"set: {exc}") from None
        return {"device": device}

    def run(self, message: dict) -> dict:
        kind = message["type"]
        if kind == "trigger":
            return self._trigger(message["name"], message.get("action", "fire"))
        if kind == "record":
            return self._record(message["action"])
        if kind == "takes":
            return {"takes": takes_under(self.session.record_root)}
        if kind == "neutral":
            self.session.neutral()
            return {}
        raise ApiError(f"{kind}: not a message a stage acts on")

    def _trigger(self, name: str, action: str) -> dict:
        try:
            self.session.trigger(name, action)
        except ValueError as exc:
            raise ApiError(f"trigger: {exc}") from None
        return {"name": name, "action": action}

    def _record(self, action: str) -> dict:
        if action == "start":
            if self.session.recording:
                raise ApiError("record: already recording")
            try:
                return {"take": str(self.start_take())}
            except (TakeError, OSError) as exc:
                raise ApiError(f"record: {exc}") from None
        if not self.session.recording:
            raise ApiError("record: not recording")
        return {"take": str(self.stop_take())}


def takes_under(root: str | Path) -> list[dict]:
    """The takes in a folder, oldest first: name, folder, frames, fps, complete."""
    found = []
    root = Path(root)
    if not root.is_dir():
        return found
    for folder in sorted(p for p in root.iterdir() if (p / META_NAME).is_file()):
        try:
            meta = open_take(folder).meta
        except (TakeError, OSError, ValueError):
            continue
        found.append({"name": folder.name, "folder": str(folder.resolve()), "frames": meta.get("frames"),
                      "fps": meta.get("fps"), "complete": bool(meta.get("complete"))})
    return found
