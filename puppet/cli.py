"""The ``puppet`` command."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .render import VIEW_DIRECTIONS

VIEWS = tuple(VIEW_DIRECTIONS)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="puppet", description="facepuppet: live facial puppeteering")
    commands = parser.add_subparsers(dest="command", required=True)

    demo = commands.add_parser("demo", help="replay the shipped demo take on the default face to a video")
    demo.add_argument("--out", default="out", help="output folder (default: out)")
    demo.add_argument("--size", type=_size, default=(640, 480), help="video size WxH (default 640x480)")

    render = commands.add_parser("render", help="render a .fap take to an MP4 video")
    render.add_argument("take", help="the .fap file")
    render.add_argument("-o", "--output", required=True, help="the video to write (.mp4)")
    render.add_argument("--size", type=_size, default=(640, 480), help="video size WxH (default 640x480)")
    render.add_argument("--view", choices=VIEWS, default="front", help="camera (default front)")
    render.add_argument("--fps", type=_positive_float, default=None, help="video fps (default: the take's)")
    render.add_argument("--face", default=None, help="a face mesh with feature points (default: the embedded face)")

    play = commands.add_parser("play", help="play a .fap take in a window, in real time")
    play.add_argument("take", help="the .fap file")
    play.add_argument("--size", type=_size, default=(960, 720), help="window size WxH (default 960x720)")
    play.add_argument("--view", choices=VIEWS, default="front", help="camera (default front)")

    live = commands.add_parser("live", help="run a mapping's devices onto the face in a window, live")
    live.add_argument("--mapping", required=True, help="the mapping YAML")
    live.add_argument("--record", default=None, metavar="NAME", help="take name for R (default: take)")
    live.add_argument("--fps", type=_positive, default=30, help="recorded take fps (default 30)")
    live.add_argument("--size", type=_size, default=(960, 720), help="window size WxH (default 960x720)")
    live.add_argument("--view", choices=VIEWS, default="front", help="camera (default front)")
    live.add_argument("--device", action="append", type=_device_override, default=[], metavar="NAME=URL",
                      help="open the mapping's device NAME at URL instead (e.g. box=sim://joystick); repeatable")

    commands.add_parser("devices", help="list the controllers that are connected (serial, HID, MIDI, CAN)")

    calibrate = commands.add_parser("calibrate", help="record rest and a sweep per channel; write them into the mapping")
    calibrate.add_argument("--mapping", required=True, help="the mapping YAML to calibrate (a .bak copy is kept)")
    calibrate.add_argument("--rest", type=_positive_float, default=2.0, help="seconds of rest to record (default 2)")
    calibrate.add_argument("--sweep", type=_positive_float, default=8.0, help="seconds of sweep to record (default 8)")

    bench = commands.add_parser("bench", help="measure Sibson precompute, rig load and per-frame deform")
    bench.add_argument("--json", action="store_true", help="print the results as JSON")
    bench.add_argument("--frames", type=_positive, default=300, help="frames per measurement")
    bench.add_argument("--no-ict", action="store_true", help="skip the ICT face even when present")

    args = parser.parse_args(argv)
    if args.command == "demo":
        from .demo import run_demo

        for path in run_demo(Path(args.out), size=args.size):
            print(path)
        return 0
    if args.command == "render":
        return _render(args)
    if args.command == "play":
        from .window import play_take

        play_take(args.take, size=args.size, view=args.view)
        return 0
    if args.command == "live":
        from .live import run_live

        run_live(args.mapping, record=args.record, fps=args.fps, size=args.size, view=args.view,
                 devices=dict(args.device) or None)
        return 0
    if args.command == "calibrate":
        return _calibrate(args)
    if args.command == "devices":
        from devices.discovery import discover, report

        print(report(discover()))
        return 0
    if args.command == "bench":
        from .bench import run_bench

        return run_bench(frames=args.frames, as_json=args.json, ict=not args.no_ict)
    return 2


def _render(args: argparse.Namespace) -> int:
    """``puppet render``: a bad take, face or path is one line on stderr and exit code 2."""
    from .face import FaceFileError, MissingFeaturePointsError, load_face
    from .fapfile import FapError
    from .playback import render_take
    from .takes import TakeError
    from .rig import RigError

    try:
        face = load_face(args.face) if args.face else None
        count = render_take(args.take, args.output, face=face, size=args.size, view=args.view, fps=args.fps,
                            progress=sys.stderr.isatty())
    except (FapError, TakeError, FaceFileError, MissingFeaturePointsError, RigError) as exc:
        print(f"puppet render: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"puppet render: {exc.filename or args.take}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(f"{args.output}: {count} frames")
    return 0


def _calibrate(args: argparse.Namespace) -> int:
    """``puppet calibrate``: a bad mapping or device is one line on stderr and exit code 1."""
    from devices import DeviceError

    from .calibrate import CalibrationError, calibrate
    from .mapping import MappingError

    try:
        calibrate(args.mapping, rest_seconds=args.rest, sweep_seconds=args.sweep)
    except (MappingError, DeviceError, CalibrationError) as exc:
        print(f"puppet calibrate: {exc}", file=sys.stderr)
        return 1
    return 0


def _device_override(text: str) -> tuple[str, str]:
    name, sep, url = text.partition("=")
    if not sep or not name or "://" not in url and ":" not in url:
        raise argparse.ArgumentTypeError(f"expected NAME=URL such as box=sim://joystick, got {text!r}")
    return name, url


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be above 0, got {text}")
    return value


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 640x480, got {text!r}") from None
    if width < 16 or height < 16:
        raise argparse.ArgumentTypeError(f"too small: {text}")
    return width, height


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


if __name__ == "__main__":
    sys.exit(main())
