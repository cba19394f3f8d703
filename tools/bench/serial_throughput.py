#!/usr/bin/env python3
"""How many samples a second ``SerialDevice`` sustains: a serial joystick writes flat out, the
device reads, this process drains it for ``--seconds``; prints samples read and drained a
second, bad frames and queue drops.

The joystick runs as ``puppet sim joystick --rate 0`` in another process (pinned to another CPU
than the reader) over a pseudo-terminal, or in a thread of this process (``--writer thread``),
or over pyserial's ``loop://`` with a writer thread (``--loop``: no tty at all):

    python tools/bench/serial_throughput.py [--seconds 3] [--protocol cobs] [--loop] [--writer thread]
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from devices import State  # noqa: E402
from devices.base import Url  # noqa: E402
from devices.serial_port import SerialDevice  # noqa: E402
from devices.serial_wire import encode_reading  # noqa: E402
from devices.simulated_serial import PtyJoystick, sine_sliders  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="how long to measure")
    parser.add_argument("--protocol", choices=["ascii", "cobs", "slip"], default="ascii")
    parser.add_argument("--channels", type=int, default=6)
    parser.add_argument("--format", choices=["i16", "f32"], default="i16", help="cobs/slip value type")
    parser.add_argument("--style", choices=["csv", "space", "pairs"], default="csv", help="ascii line style")
    parser.add_argument("--cpu", type=int, help="the reader's CPU (default: the first this process may use)")
    parser.add_argument("--loop", action="store_true", help="over loop:// instead of a pty")
    parser.add_argument("--writer", choices=["process", "thread"], default="process",
                        help="where the pty writer runs")
    args = parser.parse_args(argv)
    return bench(args)


def bench(args: argparse.Namespace) -> int:
    """Measure, print one line; the writer process and its folder are gone afterwards."""
    reader_cpu = sorted(os.sched_getaffinity(0))[0] if args.cpu is None else args.cpu
    writer_cpu = next((c for c in range(os.cpu_count() or 1) if c != reader_cpu), reader_cpu)
    os.sched_setaffinity(0, {reader_cpu})
    query = f"protocol={args.protocol}&format={args.format}" if args.protocol != "ascii" else "protocol=ascii"
    stop = threading.Event()
    writer = joystick = folder = None
    if args.loop:
        where = "loop://, writer thread in the reader's process"
        device = SerialDevice.from_url(Url.parse(f"serial:loop://?{query}"), "bench")
    elif args.writer == "thread":
        where = "pty, writer thread in the reader's process"
        joystick = PtyJoystick(args.protocol, math.inf, args.channels, fmt=args.format, style=args.style)
        joystick.start()
        device = SerialDevice.from_url(Url.parse(f"serial://{joystick.path}?{query}"), "bench")
    else:
        folder = tempfile.mkdtemp(prefix="pty-bench-")
        link = os.path.join(folder, "joystick")
        where = f"pty, writer process on CPU {writer_cpu}"
        writer = _writer_process(args, link, writer_cpu)
        device = SerialDevice.from_url(Url.parse(f"serial://{link}?{query}"), "bench")
    try:
        with device:
            if not device.wait_state(State.OPEN, 5):
                raise SystemExit(f"could not open the port: {device.counters.last_error}")
            if args.loop:
                signal = sine_sliders(args.channels)
                block = b"".join(encode_reading(signal(i / 1000), args.protocol, args.format, args.style)
                                 for i in range(256))
                threading.Thread(target=_loop_writer, args=(device.port, block, stop), daemon=True).start()
            time.sleep(0.5)  # warm up
            device.drain()
            counters = device.counters
            bad0, read0, dropped0 = counters.bad_frames, counters.samples, counters.dropped
            t0, count = time.monotonic(), 0
            while time.monotonic() - t0 < args.seconds:
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
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
        if joystick is not None:
            joystick.close()
    print(f"{args.protocol} ({args.format if args.protocol != 'ascii' else args.style}), "
          f"{args.channels} channels over {where}; reader on CPU {reader_cpu}: "
          f"{read / elapsed:,.0f} samples/s read ({read} in {elapsed:.2f} s), "
          f"{count / elapsed:,.0f}/s drained by the consumer, bad frames {bad}, queue drops {dropped}")
    return 0


def _writer_process(args: argparse.Namespace, link: str, cpu: int) -> subprocess.Popen:
    """``puppet sim joystick`` flat out behind ``link``, pinned to ``cpu``, once its link exists."""
    command = [sys.executable, "-m", "puppet.cli", "sim", "joystick", "--protocol", args.protocol, "--rate", "0",
               "--channels", str(args.channels), "--format", args.format, "--style", args.style, "--link", link]
    writer = subprocess.Popen(command, cwd=Path(__file__).resolve().parents[2], stdin=subprocess.DEVNULL,
                              stdout=subprocess.DEVNULL,
                              preexec_fn=lambda: os.sched_setaffinity(0, {cpu}))
    deadline = time.monotonic() + 10
    while not os.path.lexists(link):
        if time.monotonic() > deadline or writer.poll() is not None:
            writer.kill()
            raise SystemExit("the writer process did not start")
        time.sleep(0.02)
    return writer


def _loop_writer(port, block: bytes, stop: threading.Event) -> None:
    while not stop.is_set():
        try:
            port.write(block)
        except Exception:  # noqa: BLE001 -- the port closed under us: the bench is over
            return


if __name__ == "__main__":
    sys.exit(main())
