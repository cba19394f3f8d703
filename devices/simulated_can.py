"""A simulated CAN joystick: frames from a generated motion, sent on a python-can bus.

``CanJoystick`` opens its own python-can bus (the in-process ``virtual`` one by default: any
``can.Bus(interface="virtual", channel=...)`` with the same channel hears it, so
``can://virtual/<channel>`` reads it) and sends the two messages of ``JOYSTICK_DBC`` at ``rate``
ticks per second from a thread, or ``burst(n)`` ticks at once with no sleeping (benchmarks). The
frames are encoded by cantools from the DBC text, independently of the rig's own decoder, and
``JOYSTICK_SIGNALS`` describes the same signals in the rig's ``signals=`` form, so both ways of
reading them can be checked against each other.

Messages (both byte orders, signed and unsigned, odd lengths):

- ``JoyAxes`` 0x100, 8 bytes, Intel: JoystickX, JoystickY (16-bit signed, 0.01 %: -100..100),
  JoystickTwist (12-bit signed, 0.1 %), Throttle (12-bit unsigned, 0.025 %: 0..100), Trigger,
  ThumbButton, Button3, Button4 (1 bit), Counter (4-bit rolling) -- the names and units
  ``mappings/can_joystick.yaml`` reads;
- ``JoyExtra`` 0x101, 4 bytes, Motorola: Hat (4 bits, 0..7 clockwise from north, 8 = centred),
  Wheel (12-bit signed, -1..1), Pedal (10-bit unsigned, 0..1).
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import can
import cantools

AXES_ID, EXTRA_ID = 0x100, 0x101
BUTTONS = ("Trigger", "ThumbButton", "Button3", "Button4")
_S12, _U10 = 1 / 2047, 1 / 1023

JOYSTICK_DBC = f"""VERSION ""

NS_ :

BS_:

BU_: JOY RIG

BO_ {AXES_ID} JoyAxes: 8 JOY
 SG_ JoystickX : 0|16@1- (0.01,0) [-100|100] "%" RIG
 SG_ JoystickY : 16|16@1- (0.01,0) [-100|100] "%" RIG
 SG_ JoystickTwist : 32|12@1- (0.1,0) [-100|100] "%" RIG
 SG_ Throttle : 44|12@1+ (0.025,0) [0|100] "%" RIG
 SG_ Trigger : 56|1@1+ (1,0) [0|1] "" RIG
 SG_ ThumbButton : 57|1@1+ (1,0) [0|1] "" RIG
 SG_ Button3 : 58|1@1+ (1,0) [0|1] "" RIG
 SG_ Button4 : 59|1@1+ (1,0) [0|1] "" RIG
 SG_ Counter : 60|4@1+ (1,0) [0|15] "" RIG

BO_ {EXTRA_ID} JoyExtra: 4 JOY
 SG_ Hat : 7|4@0+ (1,0) [0|8] "" RIG
 SG_ Wheel : 3|12@0- ({_S12!r},0) [-1.0005|1] "" RIG
 SG_ Pedal : 23|10@0+ ({_U10!r},0) [0|1] "" RIG
"""

JOYSTICK_SIGNALS = ";".join([
    f"JoystickX:{AXES_ID:#x}:0:16:le:s:0.01",
    f"JoystickY:{AXES_ID:#x}:16:16:le:s:0.01",
    f"JoystickTwist:{AXES_ID:#x}:32:12:le:s:0.1",
    f"Throttle:{AXES_ID:#x}:44:12:le:u:0.025",
    *(f"{name}:{AXES_ID:#x}:{56 + k}:1:le:u" for k, name in enumerate(BUTTONS)),
    f"Counter:{AXES_ID:#x}:60:4:le:u",
    f"Hat:{EXTRA_ID:#x}:7:4:be:u",
    f"Wheel:{EXTRA_ID:#x}:3:12:be:s:{_S12!r}",
    f"Pedal:{EXTRA_ID:#x}:23:10:be:u:{_U10!r}",
])
"""The joystick's signals in ``CanSignal.parse`` form (``can://virtual/ch0?signals=...``)."""


def joystick_database() -> Any:
    return cantools.database.load_string(JOYSTICK_DBC, "dbc")


def motion(t: float, frequency: float = 0.5) -> dict[str, dict[str, float]]:
    """What the joystick's controls read at time ``t`` (seconds): message name -> signal values."""
    w = 2 * math.pi * frequency * t
    step = int(t * 4)
    return {
        "JoyAxes": {"JoystickX": 100 * math.cos(w), "JoystickY": 100 * math.sin(w),
                    "JoystickTwist": 80 * math.sin(0.5 * w), "Throttle": 50 + 50 * math.sin(w),
                    **{name: step >> k & 1 for k, name in enumerate(BUTTONS)}, "Counter": 0},
        "JoyExtra": {"Hat": step % 9, "Wheel": math.sin(1.5 * w), "Pedal": 0.5 - 0.5 * math.cos(w)},
    }


class CanJoystick:
    """Sends the joystick's frames on a python-can bus, at ``rate`` ticks per second from a thread
    (``start``/``stop``, or as a context manager), or on demand (``tick``, ``burst``)."""

    def __init__(self, channel: str = "ch0", interface: str = "virtual", rate: float = 100.0,
                 frequency: float = 0.5, **bus_kwargs: Any) -> None:
        self.db = joystick_database()
        self.axes, self.extra = self.db.get_message_by_name("JoyAxes"), self.db.get_message_by_name("JoyExtra")
        self.bus = can.Bus(interface=interface, channel=channel, **bus_kwargs)
        self.rate, self.frequency = rate, frequency
        self.sent = 0  # frames sent
        self.ticks = 0
        self.last: dict[str, float] = {}  # the values of the last tick as sent (after quantising)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def frames(self, t: float) -> list[can.Message]:
        """The two frames of one tick at time ``t``."""
        values = motion(t, self.frequency)
        values["JoyAxes"]["Counter"] = self.ticks & 0xF
        out = []
        for message in (self.axes, self.extra):
            data = message.encode(values[message.name], scaling=True, strict=False)
            out.append(can.Message(arbitration_id=message.frame_id, data=data, is_extended_id=False))
        return out

    def tick(self, t: float | None = None) -> dict[str, float]:
        """Send one tick's frames; returns their values as the receiver should decode them."""
        with self._lock:
            frames = self.frames(time.monotonic() if t is None else t)
            self.ticks += 1
            for frame in frames:
                self.bus.send(frame)
                self.sent += 1
            decoded = {}
            for frame in frames:
                decoded.update(self.db.decode_message(frame.arbitration_id, frame.data, decode_choices=False))
            self.last = {k: float(v) for k, v in decoded.items()}
            return self.last

    def burst(self, n: int, dt: float = 0.01) -> None:
        """Send ``n`` ticks back to back (2n frames), the motion advancing ``dt`` seconds a tick."""
        frames = []
        for i in range(n):  # encoded first, so that the sending is back to back
            frames += self.frames(i * dt)
            self.ticks += 1
        send = self.bus.send
        for frame in frames:
            send(frame)
        self.sent += len(frames)

    def send_raw(self, frame_id: int, data: bytes) -> None:
        """Send any frame (a short one, a foreign id) as is."""
        with self._lock:
            self.bus.send(can.Message(arbitration_id=frame_id, data=bytes(data), is_extended_id=frame_id > 0x7FF))
            self.sent += 1

    def start(self) -> CanJoystick:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="can joystick", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        period = 1.0 / self.rate
        start = next_due = time.monotonic()
        while not self._stop.is_set():
            try:
                self.tick(time.monotonic() - start)
            except can.CanError:
                pass  # nobody listening or the bus went down: a real joystick keeps sending too
            next_due = max(next_due + period, time.monotonic())
            self._stop.wait(max(0.0, next_due - time.monotonic()))

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None

    def close(self) -> None:
        self.stop()
        self.bus.shutdown()

    def __enter__(self) -> CanJoystick:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
