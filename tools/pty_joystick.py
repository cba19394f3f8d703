#!/usr/bin/env python3
"""A serial joystick with no hardware: sliders on a pseudo-terminal, for trying the live rig.

    python tools/pty_joystick.py --protocol cobs --rate 200 --channels 6

prints a stable path (a symlink to the current /dev/pts/N) and the device URL to give the rig,
e.g. ``serial:///tmp/pty-joystick?protocol=cobs``, then sends smooth sine sliders (0..1023) until
Ctrl+C. Press Enter to pull the plug (the rig's device goes LOST, the face holds its pose), Enter
again to plug it back in (a new pty behind the same path; the rig reconnects).

``--rate 0`` sends as fast as the reader takes. ``--bench SECONDS`` measures how many samples a
second ``SerialDevice`` sustains: the joystick runs flat out in another process (pinned to the
second CPU, the reader to the first) over a pty, or in a thread over ``loop://`` with ``--loop``:

    python tools/pty_joystick.py --bench 3 --protocol cobs [--loop] [--writer thread]
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from devices import State
from devices.serial_port import SerialDevice
from devices.serial_wire import encode_reading
from devices.simulated_serial import PtyJoystick, sine_sliders


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--protocol", choices=["ascii", "cobs", "slip"], default="ascii")
    parser.add_argument("--rate", type=float, default=200.0, help="readings a second (0: as fast as read)")
    parser.add_argument("--channels", type=int, default=6)
    parser.add_argument("--format", choices=["i16", "f32"], default="i16", help="cobs/slip value type")
    parser.add_argument("--style", choices=["csv", "space", "pairs"], default="csv", help="ascii line style")
    parser.add_argument("--link", default=os.path.join(tempfile.gettempdir(), "pty-joystick"),
                        help="the stable path (a symlink to the current pty)")
    parser.add_argument("--cpu", type=int, help="pin this process to one CPU")
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument("--bench", type=float, metavar="SECONDS", help="measure SerialDevice throughput")
    parser.add_argument("--loop", action="store_true", help="bench over loop:// instead of a pty")
    parser.add_argument("--writer", choices=["process", "thread"], default="process",
                        help="bench: where the pty writer runs")
    args = parser.parse_args(argv)
    if args.cpu is not None:
        os.sched_setaffinity(0, {args.cpu})
    if args.bench:
        return bench(args)
    return serve(args)


def serve(args: argparse.Namespace) -> int:
    signal.signal(signal.SIGTERM, _interrupt)  # a terminated joystick cleans up its symlink too
    rate = args.rate if args.rate > 0 else math.inf
    joystick = PtyJoystick(args.protocol, rate, args.channels, fmt=args.format, style=args.style,
                           link=args.link)
    with joystick:
        query = f"protocol={args.protocol}" + (f"&format={args.format}" if args.format != "i16" else "")
        if not args.quiet:
            print(f"pty joystick: {args.protocol}, {args.channels} channels, "
                  f"{'as fast as read' if math.isinf(rate) else f'{rate:g}/s'}")
            print(f"  stable path: {joystick.path} -> {joystick.tty}")
            print(f"  device URL:  serial://{joystick.path}?{query}")
            print("  Enter: unplug / replug;  Ctrl+C: stop", flush=True)
            threading.Thread(target=_plug_toggle, args=(joystick,), daemon=True).start()
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
    if not args.quiet:
        print(f"sent {joystick.sent} readings, dropped {joystick.dropped}")
    return 0


def _interrupt(*_: object) -> None:
    raise KeyboardInterrupt


def _plug_toggle(joystick: PtyJoystick) -> None:
    for _ in sys.stdin:
        if joystick.plugged:
            joystick.unplug()
            print("  unplugged", flush=True)
        else:
            joystick.replug()
            print(f"  plugged in: {joystick.path} -> {joystick.tty}", flush=True)


def bench(args: argparse.Namespace) -> int:
    cpus = sorted(os.sched_getaffinity(0))
    reader_cpu = cpus[0] if args.cpu is None else args.cpu
    writer_cpu = next((c for c in sorted(os.sched_getaffinity(0) | set(range(os.cpu_count() or 1)))
                       if c != reader_cpu), reader_cpu)
    os.sched_setaffinity(0, {reader_cpu})
    query = f"protocol={args.protocol}&format={args.format}" if args.protocol != "ascii" else "protocol=ascii"
    stop = threading.Event()
    writer = joystick = None
    if args.loop:
        where = "loop://, writer thread in the reader's process"
        device = SerialDevice.from_url(_url(f"serial:loop://?{query}"), "bench")
    elif args.writer == "thread":
        where = "pty, writer thread in the reader's process"
        joystick = PtyJoystick(args.protocol, math.inf, args.channels, fmt=args.format, style=args.style)
        joystick.start()
        device = SerialDevice.from_url(_url(f"serial://{joystick.path}?{query}"), "bench")
    else:
        link = os.path.join(tempfile.mkdtemp(prefix="pty-bench-"), "joystick")
        where = f"pty, writer process on CPU {writer_cpu}"
        writer = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--protocol", args.protocol,
                                   "--rate", "0", "--channels", str(args.channels), "--format", args.format,
                                   "--style", args.style, "--link", link, "--cpu", str(writer_cpu), "--quiet"],
                                  stdin=subprocess.DEVNULL)
        deadline = time.monotonic() + 10
        while not os.path.lexists(link):
            if time.monotonic() > deadline or writer.poll() is not None:
                writer.kill()
                raise SystemExit("the writer process did not start")
            time.sleep(0.02)
        device = SerialDevice.from_url(_url(f"serial://{link}?{query}"), "bench")
    try:
        with device:
            if not device.wait_state(State.OPEN, 5):
                raise SystemExit(f"could not open the port: {device.counters.last_error}")
            if args.loop:
                signal = sine_sliders(args.channels)
                block = b"".join(encode_reading(signal(i / 1000), args.protocol, args.format, args.style)
                                 for i in range(256))
                port = device.port
                threading.Thread(target=_loop_writer, args=(port, block, stop), daemon=True).start()
            time.sleep(0.5)  # warm up
            device.drain()
            counters = device.counters
            bad0, read0, dropped0 = counters.bad_frames, counters.samples, counters.dropped
            t0, count = time.monotonic(), 0
            while time.monotonic() - t0 < args.bench:
                time.sleep(0.002)
                count += len(device.drain())
            elapsed = time.monotonic() - t0
            read = counters.samples - read0
            bad, dropped = counters.bad_frames - bad0, counters.dropped - dropped0
            stop.set()
    finally:
        if writer is not None:
            writer.terminate()
            writer.wait(5)
            shutil.rmtree(os.path.dirname(link), ignore_errors=True)
        if joystick is not None:
            joystick.close()
    print(f"{args.protocol} ({args.format if args.protocol != 'ascii' else args.style}), "
          f"{args.channels} channels over {where}; reader on CPU {reader_cpu}: "
          f"{read / elapsed:,.0f} samples/s read ({read} in {elapsed:.2f} s), "
          f"{count / elapsed:,.0f}/s drained by the consumer, bad frames {bad}, queue drops {dropped}")
    return 0


def _loop_writer(port, block: bytes, stop: threading.Event) -> None:
    while not stop.is_set():
        try:
            port.write(block)
        except Exception:  # noqa: BLE001 -- the port closed under us: the bench is over
            return


def _url(text: str):
    from devices.base import Url
    return Url.parse(text)


if __name__ == "__main__":
    sys.exit(main())
