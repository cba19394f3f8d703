"""The ``puppet`` command.

Every refusal is one line on stderr and exit code 2: argparse's own (``puppet render: argument
--fps: ...``), and every ``PuppetError`` (``MappingError`` ...), ``DeviceError`` or ``OSError`` a command
raises, caught once in ``main`` as ``puppet COMMAND: message``; warnings are one line too. A
traceback is a bug.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from devices.base import DeviceError
from devices.serial_wire import FORMATS, PROTOCOLS, STYLES
from puppet.errors import PuppetError
from puppet.io.shipped import copy_mapping, mapping_path, mappings_folder, shipped_mappings

VIEWS = ("front", "three_quarter", "profile")
"""``--view`` choices (``puppet.view.renderer.VIEW_DIRECTIONS``, imported only by the commands that draw,
so ``puppet devices`` starts in well under a second)."""
ANTIALIAS_MODES = ("fxaa", "none")
"""``puppet render --antialias`` choices (``puppet.view.renderer.ANTIALIAS_MODES``)."""
PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".gif", ".tif", ".tiff", ".webp")
"""What ``puppet pick-landmarks`` opens as a photo; anything else is a face mesh."""
LANDMARKS_FILE = "landmarks.json"  # what `puppet rig` writes into the face folder when it found the landmarks
BENCH_SECTIONS = ("deform", "frames", "muscles", "inputs", "rig", "latency", "voice", "flood", "long_take", "show")
"""``puppet bench --only`` choices (``puppet.bench.run.SECTIONS``; the bench is imported only when run)."""
FACE_HELP = "a face folder (puppet rig ... -o FOLDER/, puppet face-from-photo) (default: the embedded face)"
MAX_SIDE = 8192
REFUSED = (PuppetError, DeviceError, OSError)  # MappingError, FapError ... are PuppetErrors


class _Parser(argparse.ArgumentParser):
    """argparse, with its refusals on one line (``puppet render: argument --fps: ...``)."""

    def error(self, message: str) -> None:
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")


def main(argv: list[str] | None = None) -> int:
    """Run ``puppet COMMAND ...``; return its exit code (every refusal: one line on stderr, 2)."""
    args = _parser().parse_args(argv)
    with warnings.catch_warnings():
        warnings.showwarning = _warning_line(args.command)
        try:
            if getattr(args, "mapping", None):
                args.shipped_mapping = not Path(args.mapping).exists()
                args.mapping = str(mapping_path(args.mapping))
            return COMMANDS[args.command].run(args)
        except REFUSED as exc:
            print(f"puppet {args.command}: {_one_line(exc)}", file=sys.stderr)
            return 2


def _warning_line(command: str):
    """``warnings.showwarning`` for a command: ``puppet COMMAND: warning: message``, one line."""
    def show(message, category, filename, lineno, file=None, line=None) -> None:
        print(f"puppet {command}: warning: {_one_line(Exception(str(message)))}", file=file or sys.stderr)

    return show


def _one_line(exc: BaseException) -> str:
    """An error as one line: an OSError as ``file: reason``, any message's lines joined."""
    if isinstance(exc, OSError) and not isinstance(exc, PuppetError) and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    else:
        text = str(exc) or type(exc).__name__
    return "; ".join(line.strip() for line in text.splitlines() if line.strip())


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="puppet", description="facepuppet: live facial puppeteering")
    parser.add_argument("--version", action="version", version="puppet (facepuppet) 0.2.0")
    commands = parser.add_subparsers(dest="command", required=True)
    for name, command in COMMANDS.items():
        command.arguments(commands.add_parser(name, help=command.help))
    return parser


# -- the commands: for each, its arguments and what it does ------------------------------------

def _demo_arguments(demo: argparse.ArgumentParser) -> None:
    demo.add_argument("--out", default="out", help="output folder (default: out)")
    demo.add_argument("--size", type=_size, default=(640, 480), help="video size WxH (default 640x480)")


def _demo(args: argparse.Namespace) -> int:
    """``puppet demo``: the shipped take on the default face, to a video and a still."""
    from puppet.view.demo import run_demo

    for path in run_demo(Path(args.out), size=args.size):
        print(path)
    return 0


def _render_arguments(render: argparse.ArgumentParser) -> None:
    render.add_argument("take", nargs="+", help="the take folder or .fap file (or several, one video each with "
                                                "-o DIR/); a take's sound goes into the video")
    render.add_argument("-o", "--output", default=None,
                        help="the video to write (.mp4; default: take.mp4 in the take folder, or X.mp4 beside "
                             "X.fap), or for several takes a folder (DIR/): one TAKE.mp4 each")
    render.add_argument("--scheduler", default=None,
                        help="many takes: render on a running Dask scheduler (tcp://host:8786); default: one after "
                             "another for a small batch, a local Dask cluster for a big one")
    render.add_argument("--workers", type=int, default=None,
                        help="many takes: render on a local Dask cluster of N worker processes (default: chosen by "
                             "the batch's size)")
    render.add_argument("--size", type=_size, default=(640, 480), help="video size WxH (default 640x480)")
    render.add_argument("--view", choices=VIEWS, default="front", help="camera (default front)")
    render.add_argument("--fps", type=_seconds_or_rate("fps", 0.1, 1000), default=None,
                        help="video fps (default: the take's)")
    render.add_argument("--face", default=None, help=FACE_HELP)
    render.add_argument("--antialias", choices=ANTIALIAS_MODES, default=None,
                        help="post pass smoothing edges (default: as the live window draws on this GL: "
                             "none on a software rasteriser, whose frame FXAA makes 40%% longer)")


def _window_arguments(play: argparse.ArgumentParser) -> None:
    play.add_argument("take", help="the .fap file or take folder")
    play.add_argument("--size", type=_size, default=(960, 720), help="window size WxH (default 960x720)")
    play.add_argument("--view", choices=VIEWS, default="front", help="camera (default front)")
    play.add_argument("--face", default=None, help=FACE_HELP)


SERVE_HELP = ("also serve the face as a program feed for OBS or a browser (transparent background) and the "
              "control API, on HOST:PORT (e.g. 127.0.0.1:8765; the URLs, with their token, are printed)")


PROGRAM_HELP = ("with --serve: also open the program window, the face alone on a key colour for OBS's Window "
                "Capture with a Chroma Key (puppet program)")
KEY_COLOUR_HELP = "the program window's key colour, RRGGBB in hex (default 00FF00: pure green)"


def _show_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--program", action="store_true", help=PROGRAM_HELP)
    parser.add_argument("--key-colour", type=_colour, default=(0, 255, 0), metavar="RRGGBB", help=KEY_COLOUR_HELP)
    parser.add_argument("--ndi", default=None, metavar="NAME",
                        help="also send the face as an NDI source NAME, with alpha (needs the ndi extra: cyndilib)")


def _check_shows(args: argparse.Namespace) -> None:
    """``--program`` needs ``--serve`` and a display, ``--ndi`` its extra: checked before anything opens."""
    if args.ndi is not None:
        from puppet.show.ndi import load_cyndilib

        load_cyndilib()
    if args.program and args.serve is None:
        raise PuppetError("--program needs --serve HOST:PORT: the window shows the served feed")
    if args.program:
        from puppet.view.window import NoDisplayError, check_display

        try:
            check_display()
        except NoDisplayError as exc:
            raise NoDisplayError(f"--program: {exc}") from None


def _shows(args: argparse.Namespace, face, serve: Callable) -> list:
    """The rig's outputs: the server (``serve()`` starts it) when ``--serve``, the program window
    before it (so that it closes first) when ``--program``, the NDI source when ``--ndi``."""
    made: list = []
    try:
        if args.ndi is not None:
            from puppet.show.ndi import ndi_output

            made.append(ndi_output(face, args.ndi, args.view))
        if args.serve is not None:
            server = serve()
            made.insert(0, server)
            if args.program:
                from puppet.show.program import ProgramProcess

                made.insert(0, ProgramProcess(server, args.key_colour))
    except BaseException:
        from puppet.view.liveoutput import close_outputs

        close_outputs(made)
        raise
    return made


def _play_arguments(play: argparse.ArgumentParser) -> None:
    _window_arguments(play)
    play.add_argument("--serve", type=_address, default=None, metavar="HOST:PORT", help=SERVE_HELP)
    _show_options(play)


def _play(args: argparse.Namespace) -> int:
    """``puppet play``: a take in a window, in real time."""
    from puppet.view.window import play_take

    _check_shows(args)
    outputs = None
    if args.serve is not None or args.ndi is not None:
        def outputs(face):
            from puppet.show.serving import serve_playback

            return _shows(args, face, lambda: serve_playback(face, args.serve, args.view))
    play_take(args.take, size=args.size, view=args.view, face=_face(args.face), outputs=outputs)
    return 0


def _replay_arguments(replay: argparse.ArgumentParser) -> None:
    _window_arguments(replay)
    replay.add_argument("--through-devices", action="store_true",
                        help="re-encode the raw log into each device's wire format and read it back with the "
                             "real adapters; the new .fap must equal the recorded one")
    replay.add_argument("--mapping", default=None, help="re-map the take's raw log with this mapping YAML")
    replay.add_argument("-o", "--output", default=None,
                        help="the new .fap (default: replay.fap or remap-<mapping>.fap in the take folder)")
    replay.add_argument("--no-window", action="store_true", help="write the new .fap only; do not play it")


def _export_arguments(export: argparse.ArgumentParser) -> None:
    export.add_argument("take", help="the .fap file or take folder")
    export.add_argument("-o", "--output", required=True, help="the .glb to write")
    export.add_argument("--mode", choices=("morph", "frames"), default="morph",
                        help="morph: a compressed morph-target basis (default); frames: one target per frame")
    export.add_argument("--max-frames", type=_positive, default=None, help="export only the first N frames")
    export.add_argument("--face", default=None, help=FACE_HELP)


def _import_arkit_arguments(arkit: argparse.ArgumentParser) -> None:
    arkit.add_argument("csv", help="the CSV file")
    arkit.add_argument("--mapping", default=None, help="ARKit names -> FAPs (default: mappings/arkit_csv.yaml)")
    arkit.add_argument("--name", default="arkit", help="take name (default arkit: folders arkit_001, ...)")
    arkit.add_argument("--takes", default="takes", help="folder for takes (default takes)")
    arkit.add_argument("--fps", type=int, choices=(25, 30, 50, 60), default=30, help="take fps (default 30)")
    arkit.add_argument("--csv-fps", type=_seconds_or_rate("fps", 0.1, 1000), default=60.0,
                       help="the rate of the timecodes' frame field (default 60)")


def _lipsync_arguments(lipsync: argparse.ArgumentParser) -> None:
    lipsync.add_argument("sound", help="a recording of speech (any format libsndfile reads: WAV, FLAC, Ogg ...)")
    lipsync.add_argument("-o", "--output", required=True, metavar="TAKE/",
                         help="the take folder to write (new or empty): take.fap, take.wav, the log, take.json")
    lipsync.add_argument("--mapping", default=None,
                         help="what the voice drives: a mapping with an audio:// or wav:// device (default: voice)")
    lipsync.add_argument("--over", default=None, metavar="TAKE",
                         help="lay the mouth over this take, keeping the rest of it (a layered pass)")
    lipsync.add_argument("--fps", type=int, choices=(25, 30, 50, 60), default=30, help="take fps (default 30)")
    lipsync.add_argument("--live", action="store_true",
                         help="analyse as a live microphone does (no look-ahead): the take a live pass would give")
    lipsync.add_argument("--script", default=None, metavar="WORDS",
                         help="the words said: aligned to the sound, they shape the mouth phone by phone (espeak-ng)")
    lipsync.add_argument("--language", default="en-us",
                         help="the script's language, as espeak-ng names it (default en-us; espeak-ng --voices)")


def _lipsync(args: argparse.Namespace) -> int:
    """``puppet lipsync``: a speech recording into a take with its sound."""
    import time

    from puppet.io.takes import open_take
    from puppet.live.lipsync import lipsync

    start = time.perf_counter()
    folder = lipsync(args.sound, args.output, mapping=args.mapping, over=args.over, fps=args.fps,
                     lookahead=not args.live, script=args.script, language=args.language)
    meta = open_take(folder).meta
    seconds = meta["frames"] / meta["fps"]
    print(f"{folder}: {meta['frames']} frames ({seconds:.1f} s) with its sound, in "
          f"{time.perf_counter() - start:.1f} s; puppet render {folder} makes the video")
    return 0


def _live_arguments(live: argparse.ArgumentParser) -> None:
    live.add_argument("--mapping", required=True, help="the mapping: a YAML file or a shipped name (puppet mappings)")
    live.add_argument("--record", default=None, metavar="NAME", help="take name for R (default: take)")
    live.add_argument("--takes", default="takes", metavar="DIR",
                      help="folder the takes go to (default: ./takes; printed when recording starts)")
    live.add_argument("--fps", type=int, choices=(25, 30, 50, 60), default=30, help="recorded take fps (default 30)")
    live.add_argument("--size", type=_size, default=(960, 720), help="window size WxH (default 960x720)")
    live.add_argument("--view", choices=VIEWS, default="front", help="camera (default front)")
    live.add_argument("--device", action="append", type=_device_override, default=[], metavar="NAME=URL",
                      help="open the mapping's device NAME at URL instead (e.g. box=sim://joystick); repeatable")
    live.add_argument("--face", default=None, help=FACE_HELP)
    live.add_argument("--layer-over", default=None, metavar="TAKE",
                      help="record passes over this take: it plays under you, and only --arm is replaced")
    live.add_argument("--arm", default="", metavar="A,B",
                      help="what a layered pass replaces: channels (box.ch0), FAP numbers or names, viseme, expression")
    live.add_argument("--serve", type=_address, default=None, metavar="HOST:PORT", help=SERVE_HELP)
    live.add_argument("--osc-control", type=_address, default=None, metavar="HOST:PORT",
                      help="with --serve: also take the control API as OSC messages on this UDP address "
                           "(/puppet/set/CHANNEL, /puppet/trigger/NAME, /puppet/record/start|stop, /puppet/neutral)")
    live.add_argument("--no-window", action="store_true",
                      help="no window, only the --serve feed and API or the --ndi source (e.g. on a machine with no "
                           "display); Ctrl+C ends")
    _show_options(live)


def _live(args: argparse.Namespace) -> int:
    """``puppet live``: the mapping's devices onto the face in the live window."""
    from puppet.io.takes import TakeError
    from puppet.view.livewindow import run_live

    if args.layer_over and not args.arm:
        raise TakeError("--layer-over needs --arm: what the pass replaces (e.g. --arm box.ch0)")
    if args.arm and not args.layer_over:
        raise TakeError("--arm needs --layer-over: the take the pass is recorded over")
    if args.serve is None and args.osc_control:
        raise PuppetError("--osc-control needs --serve HOST:PORT")
    if args.serve is None and args.ndi is None and args.no_window:
        raise PuppetError("--no-window needs --serve HOST:PORT or --ndi NAME")
    _check_shows(args)
    outputs = None
    if args.serve is not None or args.ndi is not None:
        def outputs(session):
            from puppet.show.serving import serve_live

            return _shows(args, session.runtime.face,
                          lambda: serve_live(session, args.serve, args.view, args.osc_control))
    run_live(args.mapping, record=args.record, fps=args.fps, size=args.size, view=args.view,
             devices=dict(args.device) or None, face=_face(args.face), layer_over=args.layer_over,
             arm=[a for a in args.arm.split(",") if a], record_root=args.takes, outputs=outputs,
             window=not args.no_window)
    return 0


def _program_arguments(program: argparse.ArgumentParser) -> None:
    program.add_argument("url", help="the program feed URL that puppet live --serve (or puppet play --serve) printed")
    program.add_argument("--key-colour", type=_colour, default=(0, 255, 0), metavar="RRGGBB", help=KEY_COLOUR_HELP)
    program.add_argument("--size", type=_size, default=(720, 720), help="window size WxH (default 720x720)")


def _program(args: argparse.Namespace) -> int:
    """``puppet program``: a served face alone on a key colour, in a window for window capture."""
    from puppet.show.program import run_program

    if run_program(args.url, args.key_colour, args.size) == "feed ended":
        print("puppet program: the feed ended (the rig stopped)", file=sys.stderr)
    return 0


def _devices(args: argparse.Namespace) -> int:
    """``puppet devices``: what is plugged in, as device URLs."""
    from devices.discovery import discover, report

    print(report(discover()))
    return 0


def _sim_arguments(sim: argparse.ArgumentParser) -> None:
    sim.add_argument("device", choices=("joystick",),
                     help="joystick: a serial slider box on a pseudo-terminal, behind a stable path")
    sim.add_argument("--protocol", choices=PROTOCOLS, default="ascii",
                     help="the wire: ASCII lines, COBS or SLIP frames (default ascii)")
    sim.add_argument("--rate", type=_seconds_or_rate("readings a second", 0, 1e6), default=200.0,
                     help="readings a second (default 200; 0: as fast as they are read)")
    sim.add_argument("--channels", type=_positive, default=6, help="sliders (default 6)")
    sim.add_argument("--format", choices=sorted(FORMATS), default="i16",
                     help="cobs and slip: the value type (default i16)")
    sim.add_argument("--style", choices=sorted(STYLES), default="csv",
                     help="ascii: csv (512,300), space (512 300) or pairs (ch0=512,ch1=300) (default csv)")
    sim.add_argument("--link", default=None, metavar="PATH",
                     help="the stable path, a symlink to the current /dev/pts/N (default: pty-joystick in the "
                          "temporary folder)")


def _sim(args: argparse.Namespace) -> int:
    """``puppet sim joystick``: sine sliders on a pseudo-terminal until Ctrl+C; Enter pulls the plug
    or puts it back (a new pty behind the same path), so a rig reading it sees LOST and a reconnect."""
    import signal
    import tempfile
    import threading
    import time

    from devices.simulated_serial import PtyJoystick

    signal.signal(signal.SIGTERM, _interrupt)  # terminated, it removes its symlink as on Ctrl+C
    link = args.link or os.path.join(tempfile.gettempdir(), "pty-joystick")
    query = f"protocol={args.protocol}" + (f"&format={args.format}" if args.format != "i16" else "")
    with PtyJoystick(args.protocol, args.rate or math.inf, args.channels, fmt=args.format, style=args.style,
                     link=link) as joystick:
        print(f"sim joystick: {args.protocol}, {args.channels} channels, "
              f"{f'{args.rate:g}/s' if args.rate else 'as fast as read'}")
        print(f"  stable path: {joystick.path} -> {joystick.tty}")
        print(f"  device URL:  serial://{joystick.path}?{query}")
        print("  Enter: unplug / replug;  Ctrl+C: stop", flush=True)
        threading.Thread(target=_plug_toggle, args=(joystick,), daemon=True).start()
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
    print(f"sent {joystick.sent} readings, dropped {joystick.dropped}")
    return 0


def _interrupt(*_: object) -> None:
    raise KeyboardInterrupt


def _plug_toggle(joystick) -> None:
    """Each line on stdin pulls the joystick's plug, or puts it back."""
    for _ in sys.stdin:
        if joystick.plugged:
            joystick.unplug()
            print("  unplugged", flush=True)
        else:
            joystick.replug()
            print(f"  plugged in: {joystick.path} -> {joystick.tty}", flush=True)


def _mappings_arguments(mappings: argparse.ArgumentParser) -> None:
    mappings.add_argument("--copy", metavar="NAME", default=None, help="write NAME.yaml here (or to -o) to edit")
    mappings.add_argument("-o", "--output", default=".", help="folder or file for --copy (default: here)")


def _calibrate_arguments(calibrate: argparse.ArgumentParser) -> None:
    calibrate.add_argument("--mapping", required=True,
                           help="the mapping YAML to calibrate (a .bak copy is kept; copy a shipped one first)")
    calibrate.add_argument("--device", action="append", type=_device_override, default=[], metavar="NAME=URL",
                           help="open the mapping's device NAME at URL instead (e.g. box=sim://joystick); repeatable")
    calibrate.add_argument("--rest", type=_seconds_or_rate("seconds", 0.1, 600), default=2.0,
                           help="seconds of rest to record (default 2)")
    calibrate.add_argument("--sweep", type=_seconds_or_rate("seconds", 0.1, 600), default=8.0,
                           help="seconds of sweep to record (default 8)")


def _calibrate_face_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--examples", required=True,
                        help="a folder of example shapes of the face: .obj meshes of its own vertices in new shapes, "
                             "or MakeHuman .target files for a face cut from MakeHuman's mesh (the embedded one); "
                             "or the .glb / .gltf / .vrm the face was rigged from: its morph targets and expressions")
    parser.add_argument("--face", default=None, help=FACE_HELP)
    parser.add_argument("-o", "--output", required=True,
                        help="the face folder to write (the face with its calibrated rig; it may be --face's own), "
                             "or a .rig file")
    parser.add_argument("--hold-out", nargs="+", default=[], metavar="NAME",
                        help="examples the calibration does not learn from; their fit is reported apart")


def _bench_arguments(bench: argparse.ArgumentParser) -> None:
    bench.add_argument("--json", action="store_true", help="print the results as JSON")
    bench.add_argument("--frames", type=_positive, default=300, help="frames per measurement")
    bench.add_argument("--no-ict", action="store_true", help="skip the ICT face even when present")
    bench.add_argument("--flood-seconds", type=_seconds_or_rate("seconds", 0.1, 3600), default=60.0,
                       help="how long the flood runs (default 60)")
    bench.add_argument("--flood-rate", type=_seconds_or_rate("readings/s", 1, 100_000), default=10_000.0,
                       help="readings a second the flood's device sends (default 10000)")
    bench.add_argument("--take-seconds", type=_seconds_or_rate("seconds", 0.1, 86400), default=3600.0,
                       help="length of the accelerated long take (default 3600)")
    bench.add_argument("--quick", action="store_true",
                       help="a minute's worth: 30 frames, no subdivided meshes or ICT, a 3 s flood, a 1 minute take")
    bench.add_argument("--only", type=_sections, default=None, metavar="A,B",
                       help="measure only these sections: " + ", ".join(BENCH_SECTIONS))


def _bench(args: argparse.Namespace) -> int:
    """``puppet bench``: the measured sections, as tables or JSON."""
    from puppet.bench.run import run_bench

    return run_bench(frames=args.frames, as_json=args.json, ict=not args.no_ict,
                     flood_seconds=args.flood_seconds, take_seconds=args.take_seconds,
                     only=args.only or BENCH_SECTIONS, quick=args.quick, flood_rate=args.flood_rate)


def _rig_arguments(rig: argparse.ArgumentParser) -> None:
    rig.add_argument("mesh", help="the face mesh (.obj with its .mtl, .glb, .gltf, .vrm, or any format trimesh reads)")
    rig.add_argument("--landmarks", default=None,
                     help="JSON: {FDP id: vertex index} or a list of the 68 iBUG landmark vertex indices; default: "
                          "found on renders of the mesh (MediaPipe, the photo set-up) and written to landmarks.json")
    rig.add_argument("-o", "--output", required=True,
                     help="the face folder to write (mesh, feature points, rig); a name ending .rig writes the rig alone")


def _face_from_photo_arguments(from_photo: argparse.ArgumentParser) -> None:
    from_photo.add_argument("photo", help="the frontal photo")
    from_photo.add_argument("--landmarks", default=None,
                            help="landmark JSON: fdp11, iBUG 68 or MediaPipe 468/478 points (puppet pick-landmarks); "
                                 "default: detected offline (MediaPipe, the photo set-up)")
    from_photo.add_argument("-o", "--output", required=True, help="the face folder to write")


def _pick_landmarks_arguments(pick: argparse.ArgumentParser) -> None:
    pick.add_argument("photo", help="the photo, or a face mesh (.obj, .glb, ...: its feature points on a front render)")
    pick.add_argument("--layout", choices=("fdp11", "ibug68", "mediapipe468"), default="fdp11",
                      help="a photo: points to click (fdp11, the default; ibug68) or to drag into place (mediapipe468)")
    pick.add_argument("--start", help="mediapipe468: landmark JSON to start from (default: detected, the photo "
                                      "set-up); a mesh: its landmark JSON, as puppet rig wrote it (default: found)")
    pick.add_argument("-o", "--output", required=True, help="the landmark JSON to write")
    pick.add_argument("--port", type=_port, default=0, help="port 1-65535 (default: a free one)")
    pick.add_argument("--no-browser", action="store_true", help="print the address only")


def _mappings(args: argparse.Namespace) -> int:
    """``puppet mappings``: the shipped mappings by name with the start of their description, or
    ``--copy NAME``: an editable copy (never over an existing file)."""
    if args.copy:
        print(copy_mapping(args.copy, args.output))
        return 0
    shipped = shipped_mappings()
    width = max(map(len, shipped))
    for name, path in shipped.items():
        print(f"{name:{width}}  {_summary(path.read_text(encoding='utf-8'))}")
    print(f"({mappings_folder()}; use a name with --mapping, or --copy NAME to edit one)")
    return 0


def _summary(text: str, most: int = 90) -> str:
    """A mapping's ``description:`` line (else its first comment), cut at a word within ``most``."""
    found = re.search(r"^description:[ \t]*(.+)$", text, re.M)
    comments = (line.lstrip("# ").strip() for line in text.splitlines() if "$schema" not in line)
    line = found.group(1).strip().strip("'\"") if found else next((c for c in comments if c), "")
    if len(line) <= most:
        return line
    return line[:most - 3].rsplit(" ", 1)[0].rstrip(",;:") + "..."


def _sections(text: str) -> tuple[str, ...]:
    """``--only``: bench sections, comma-separated."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in BENCH_SECTIONS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"expected some of {', '.join(BENCH_SECTIONS)}, found {text!r}")
    return names


def _rig(args: argparse.Namespace) -> int:
    """``puppet rig``: landmarks -> feature points -> rig, with the time and a summary, written as a
    face folder (mesh, feature points, rig: ``--face FOLDER`` everywhere) or, for ``-o X.rig``, the
    rig file alone (``Runtime(load_face(mesh, landmarks=...), rig.load_rig(path))``)."""
    import time

    from puppet.face.autorig import build_rig
    from puppet.face.folder import write_rigged_folder
    from puppet.face.load import load_face
    from puppet.face.rig import save_rig
    from puppet.runtime.foldlimits import FOLD_STEPS, fold_limited

    output, rig_file = _rig_output(args.output)
    start = time.perf_counter()
    found, marks = None, output.with_suffix(".landmarks.json") if rig_file else output / LANDMARKS_FILE
    if args.landmarks is None:
        face, found = _found_landmarks(args.mesh, marks, 2 + len(FOLD_STEPS))
    else:
        face = load_face(args.mesh, landmarks=args.landmarks)  # the inputs checked before any step is said
    first = 1 + (found is not None)
    steps = first + len(FOLD_STEPS)
    _step("rig", first, steps, f"regions, control points and muscles on {len(face.vertices):,} vertices")
    rig = build_rig(face)
    seconds = time.perf_counter() - start
    start = time.perf_counter()
    said = iter(range(first + 1, steps + 1))
    rig = fold_limited(face, rig, step=lambda what: _step("rig", next(said), steps, what))
    limits = time.perf_counter() - start
    if rig_file:
        save_rig(rig, output)
    else:
        write_rigged_folder(face, rig, output, source_mesh=str(args.mesh))
    counts = {role: sum(p.role == role for p in rig.control_points) for role in ("active", "fixed", "passive", "interpolated")}
    print(f"rigged {args.mesh} ({len(face.vertices)} vertices) in {seconds:.2f} s -> {args.output}")
    if found is not None:
        print(f"  landmarks: {found.summary()}; written to {marks}: correct them with "
              f"`puppet pick-landmarks {args.mesh} --start {marks} -o FILE`, then rig with --landmarks FILE")
    print(f"  regions: {', '.join(f'{r.name} ({len(r.vertices)})' for r in rig.regions)}")
    print(f"  control points: {len(rig.control_points)} ({', '.join(f'{n} {k}' for k, n in counts.items())})")
    print(f"  muscles: {len(getattr(rig, 'muscles', []))}")
    print(f"  {_fold_limits_line(rig)} (found in {limits:.1f} s)")
    if not rig_file:
        print(f"  use it with --face {args.output} (play, render, replay, live, export)")
    return 0


def _found_landmarks(mesh: str, out: Path, steps: int):
    """``puppet rig`` without ``--landmarks``: the mesh (checked before any step is said), its
    landmarks found on renders (``puppet.view.meshlandmarks``) and applied; the landmarks written
    to ``out`` ({FDP id: vertex}, what ``--landmarks`` takes), for the user to correct; the first
    of the command's ``steps``."""
    import json

    from puppet.face.meshfile import load_mesh
    from puppet.photo.detect import detector_python
    from puppet.view.meshlandmarks import found_face

    bare = load_mesh(mesh)
    detector_python(mesh)
    _step("rig", 1, steps, "landmarks: the mesh rendered from 5 sides, MediaPipe's landmarks found and lifted onto it")
    face, found = found_face(bare, mesh, step=lambda text: print(f"rig: {text}", file=sys.stderr, flush=True))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(found.fdp, indent=1) + "\n", encoding="utf-8")
    return face, found


def _step(command: str, k: int, n: int, what: str) -> None:
    """A long command's progress: the step it starts, on stderr as it starts."""
    print(f"{command} {k}/{n}: {what}", file=sys.stderr, flush=True)


def _rig_output(path: str) -> tuple[Path, bool]:
    """Where ``-o`` writes a rig, and whether alone: a name ending .rig (or .json) is the rig file,
    anything else a face folder (``_folder_output``)."""
    from puppet.io.outputs import writable

    if Path(path).suffix.lower() in (".rig", ".json"):
        return writable(path, "rig file"), True
    return _folder_output(path), False


def _folder_output(path: str) -> Path:
    """A face folder to write: new, or an existing folder (never a file)."""
    from puppet.io.outputs import OutputError, writable

    folder = Path(path)
    if folder.is_dir():
        return folder
    if folder.exists():
        raise OutputError(f"{folder}: expected a folder for the face (or a .rig file name), found a file")
    return writable(folder, "face folder")


def _render(args: argparse.Namespace) -> int:
    """``puppet render``: the take (file or folder) and the output are checked before any frame."""
    import time

    from puppet.view.rendertake import render_take

    if args.output is None:
        if len(args.take) > 1:
            raise PuppetError("several takes: give -o DIR/ for their videos")
        args.output = str(_default_video(args.take[0]))
    if len(args.take) > 1 or args.output.endswith(("/", os.sep)) or os.path.isdir(args.output):
        return _render_many(args)
    args.take = args.take[0]
    face = _face(args.face)
    start = time.perf_counter()
    count = render_take(args.take, args.output, face=face, size=args.size, view=args.view, fps=args.fps,
                        progress=sys.stderr.isatty(), antialias=args.antialias)
    seconds = time.perf_counter() - start
    print(f"{args.output}: {count} frames in {seconds:.1f} s ({count / max(seconds, 1e-9):.1f} frames/s)")
    return 0


def _default_video(take: str) -> Path:
    """Where ``puppet render TAKE`` writes without ``-o``: ``take.mp4`` in a take folder, or
    ``X.mp4`` beside ``X.fap``."""
    path = Path(take)
    return path / "take.mp4" if path.is_dir() else path.with_suffix(".mp4")


def _render_many(args: argparse.Namespace) -> int:
    """``puppet render TAKE... -o DIR/``: a line per take as it finishes (video, frames, sha256, or
    the error); exit code 2 if any take failed, the others rendered all the same."""
    from puppet.view.batch import RenderSettings, check_takes, choose_runner, render_batch, render_serial

    def report(result) -> None:
        if result.ok:
            print(f"{result.video}: {result.frames} frames sha256 {result.sha256}", flush=True)
        else:
            print(f"puppet render: {result.error}", file=sys.stderr, flush=True)

    settings = RenderSettings(size=args.size, view=args.view, fps=args.fps, face=args.face,
                              antialias=args.antialias)
    check_takes(args.take, args.output)  # two takes for one video: refused before anything is said
    runner = choose_runner(args.take, scheduler=args.scheduler, workers=args.workers)
    print(f"rendering {len(args.take)} takes {runner.why}", file=sys.stderr, flush=True)
    if runner.dask:
        results = render_batch(args.take, args.output, settings, scheduler=args.scheduler,
                               workers=runner.workers, on_result=report)
    else:
        results = render_serial(args.take, args.output, settings, on_result=report)
    return 0 if all(result.ok for result in results) else 2


def _replay(args: argparse.Namespace) -> int:
    """``puppet replay``: a window on the take, or its log replayed into a new .fap (then shown).
    Exit code 1 when the new .fap differs from the recorded one or that one cannot be read."""
    from puppet.io.takes import open_take
    from puppet.live.retake import retake
    from puppet.view.window import play_take

    path = args.take
    if args.through_devices or args.mapping or args.output:
        take = open_take(args.take)
        name = "replay.fap" if args.mapping is None else f"remap-{Path(args.mapping).stem}.fap"
        result = retake(take, args.output or take.folder / name, mapping=args.mapping,
                        through_devices=args.through_devices)
        if result.unreadable:
            same = f"not compared: {result.unreadable}"
        else:
            same = {True: "identical to the recorded take.fap",
                    False: "DIFFERS from the recorded take.fap", None: "re-mapped"}[result.identical]
        print(f"{result.path}: {result.frames} frames, {same}")
        if result.identical is False or result.unreadable:
            return 1
        path = result.path
    if not args.no_window:
        play_take(path, size=args.size, view=args.view, face=_face(args.face))
    return 0


def _face(path: str | None):
    """``--face``: the face at ``path`` (a face folder or a rigged mesh), or None for the embedded one."""
    if path is None:
        return None
    from puppet.face.load import load_face
    from puppet.face.model import FaceFileError

    face = load_face(path)
    if not face.feature_points:
        stem = Path(path).stem or "myface"
        raise FaceFileError(f"{path}: a bare mesh has no feature points to rig it by; rig it once with "
                            f"`puppet rig {path} --landmarks POINTS.json -o {stem}/`, then use --face {stem}/")
    return face


def _export(args: argparse.Namespace) -> int:
    """``puppet export``: a take to .glb."""
    from puppet.face.default import DEFAULT_UNIT_MM
    from puppet.view.gltf import error_words, export_glb

    info = export_glb(args.take, args.output, mode=args.mode, max_frames=args.max_frames, face=_face(args.face),
                      step=lambda k, n, what: _step("export", k, n, what))
    error = error_words(info["max_error"], info["extent"], DEFAULT_UNIT_MM if args.face is None else None)
    print(f"{args.output}: {info['frames']} frames, {info['targets']} morph targets, {error}, {info['bytes']:,} bytes")
    return 0


def _import_arkit(args: argparse.Namespace) -> int:
    """``puppet import-arkit``: a Live Link Face CSV to a take."""
    from puppet.live.arkit import DEFAULT_MAPPING, import_csv

    folder = import_csv(args.csv, args.takes, args.name, args.fps, args.mapping or DEFAULT_MAPPING,
                        args.csv_fps)
    print(folder)
    return 0


def _calibrate(args: argparse.Namespace) -> int:
    """``puppet calibrate``: record, then write the ranges into the mapping."""
    from puppet.live.calibrate import CalibrationError, calibrate

    if args.shipped_mapping:
        name = Path(args.mapping).stem
        raise CalibrationError(f"{name} is a shipped mapping: calibrate your own copy (puppet mappings --copy "
                               f"{name}, then puppet calibrate --mapping {name}.yaml)")
    calibrate(args.mapping, rest_seconds=args.rest, sweep_seconds=args.sweep, urls=dict(args.device))
    return 0


def _calibrate_face(args: argparse.Namespace) -> int:
    """``puppet calibrate-face``: how each FAP moves this face's skin, learnt from example shapes and
    made fold-safe (``puppet.runtime.foldlimits.fold_safe_calibration``, as the embedded face's rig
    is made), written as a face folder or a rig file, with the fit on the examples (the held-out
    ones apart: what the calibration does on shapes it never saw); a folder also gets the face's
    own ARKit route when examples are named after ARKit's blendshapes (``_arkit_route``)."""
    import shutil
    import time

    from puppet.face.autorig import rig_for_face
    from puppet.face.examples import ExampleError, load_examples
    from puppet.face.folder import FACE_RIG, write_rigged_folder
    from puppet.face.load import load_face
    from puppet.face.rig import save_rig
    from puppet.runtime.foldlimits import fold_safe_calibration

    output, rig_file = _rig_output(args.output)
    face = _face(args.face) or load_face()
    examples = load_examples(face, args.examples)
    unknown = sorted(set(args.hold_out) - set(examples))
    if unknown:
        raise ExampleError(f"--hold-out {', '.join(unknown)}: no such shape in {args.examples} "
                           f"(it has {', '.join(examples)})")
    start = time.perf_counter()
    result = fold_safe_calibration(face, examples, rig=rig_for_face(face), held_out=tuple(args.hold_out))
    seconds = time.perf_counter() - start
    if rig_file:
        save_rig(result.rig, output)
    elif args.face is not None and Path(args.face).is_dir():
        if output.resolve() != Path(args.face).resolve():
            shutil.copytree(args.face, output, dirs_exist_ok=True)
        save_rig(result.rig, output / FACE_RIG)
    else:
        write_rigged_folder(face, result.rig, output, source_mesh=args.face or "the embedded default face")
    print(f"calibrated {face.name} from {_count(len(result.weights) - len(result.held_out), 'example shape')} in "
          f"{seconds:.0f} s -> {args.output}")
    for line in _fit_lines(face, result, examples):
        print(f"  {line}")
    if not rig_file:
        print(f"  use it with --face {args.output}")
        _arkit_route(face, result, examples, output, args.output)
    return 0


def _arkit_route(face, result, examples, output: Path, shown: str) -> None:
    """The face's own ARKit route (``puppet.live.arkitroute``) in its folder, when it learnt from
    ARKit-named examples, and how to use it; else an earlier route there is removed."""
    import numpy as np

    from puppet.live.arkitroute import arkit_document, remove_face_route, write_face_route

    document = arkit_document(face, result, examples, face_label=f"face {face.name!r} as calibrated")
    if not document["faps"]:
        removed = remove_face_route(output)
        if removed:
            print(f"  removed its earlier ARKit route ({', '.join(p.name for p in removed)}): fitted to the rig "
                  "this calibration replaces, with no ARKit-named shape to fit it again")
        return
    write_face_route(document, output, f"face {face.name!r} ({shown})")
    route = Path(shown)
    print(f"  its ARKit route, from {_count(len(document['faps']), 'ARKit shape')} "
          f"(median residual {float(np.median(list(document['residual'].values()))):.3f}): "
          f"{route / 'arkit_osc.yaml'} and {route / 'arkit_csv.yaml'}")
    print(f"    puppet live --face {shown} --mapping {route / 'arkit_osc.yaml'}")
    print(f"    puppet import-arkit TAKE.csv --mapping {route / 'arkit_csv.yaml'}")


def _fit_lines(face, result, examples) -> list[str]:
    """The calibration's fit of its examples (learnt from, held out), within the fold limits."""
    import numpy as np

    from puppet.runtime.fapcalibration import relative_residual
    from puppet.runtime.runtime import Runtime

    runtime = Runtime(face, result.rig, dtype=np.float64)
    residual = {name: relative_residual(runtime, values, examples[name]) for name, values in result.weights.items()}
    lines = ["fit, relative residual |V(f) - V0 - D| / |D| over the vertices a shape moves, within the fold limits:"]
    for label, names in (("learnt from", [n for n in residual if n not in result.held_out]),
                         ("held out", list(result.held_out))):
        if names:
            worst = max(names, key=residual.get)
            lines.append(f"{label + ':':13} median {np.median([residual[n] for n in names]):.3f}, "
                         f"worst {residual[worst]:.3f} ({worst}), {_count(len(names), 'shape')}")
    lines.append(_fold_limits_line(result.rig))
    return lines


def _fold_limits_line(rig) -> str:
    """What a rig's fold limits and smoothing hold (``puppet.runtime.foldlimits``, ``creasesmoothing``)."""
    smoothed = f", {len(rig.smoothed)} smoothed where they crease" if len(rig.smoothed) else ""
    return (f"fold limits: {len(rig.fap_reach)} FAPs capped, {len(rig.fap_follow)} lip pairs following each other, "
            f"{len(rig.guarded)} vertices guarded where the expressions and visemes fold{smoothed}")


def _count(n: int, noun: str) -> str:
    """``n`` and the noun, plural unless one."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _face_from_photo(args: argparse.Namespace) -> int:
    """``puppet face-from-photo``: a face folder from a photo and its landmarks."""
    from puppet.photo.build import build_face_folder

    print(build_face_folder(args.photo, args.landmarks, args.output,
                            step=lambda k, n, what: _step("face-from-photo", k, n, what)))
    return 0


def _pick_landmarks(args: argparse.Namespace) -> int:
    """``puppet pick-landmarks``: serve the picker until the points are saved."""
    import webbrowser

    from puppet.io.outputs import writable
    from puppet.view.picker import PickerServer

    start = None
    out = writable(args.output, "landmark file")
    if Path(args.photo).suffix.lower() in PHOTO_SUFFIXES:
        if args.layout == "mediapipe468":
            from puppet.photo.build import read_landmarks_json
            from puppet.photo.detect import detect_landmarks

            start = read_landmarks_json(args.start) if args.start else detect_landmarks(args.photo)
        picker = PickerServer(args.photo, args.layout, out, port=args.port, start=start)
    else:
        from puppet.view.meshpicker import MeshPickerServer

        picker = MeshPickerServer(args.photo, out, port=args.port, start=args.start)
    print(f"{'drag' if picker.start else 'click'} the points at {picker.url} (Ctrl-C to give up)")
    if not args.no_browser:
        webbrowser.open(picker.url)
    try:
        print(picker.wait())
    except KeyboardInterrupt:
        picker.close()
        return 1
    return 0


def _device_override(text: str) -> tuple[str, str]:
    name, sep, url = text.partition("=")
    if not sep or not name or "://" not in url and ":" not in url:
        raise argparse.ArgumentTypeError(f"expected NAME=URL such as box=sim://joystick, got {text!r}")
    return name, url


def _seconds_or_rate(unit: str, least: float, most: float):
    """An argparse type: a number from ``least`` to ``most`` (``unit`` names it in messages)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not least <= value <= most:
            raise argparse.ArgumentTypeError(f"expected {unit} as a number from {least:g} to {most:g},"
                                             f" got {text!r}")
        return value

    return parse


def _address(text: str) -> tuple[str, int]:
    """An argparse type: HOST:PORT for a server to listen on."""
    host, _, port = text.rpartition(":")
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT such as 127.0.0.1:8765, got {text!r}")
    return host.strip("[]") or "127.0.0.1", int(port)


def _colour(text: str) -> tuple[int, int, int]:
    """An argparse type: a colour as RRGGBB (or #RRGGBB) in hex, as three bytes."""
    match = re.fullmatch(r"#?([0-9a-fA-F]{6})", text.strip())
    if match is None:
        raise argparse.ArgumentTypeError(f"expected a colour as RRGGBB in hex such as 00FF00, got {text!r}")
    value = int(match.group(1), 16)
    return value >> 16, (value >> 8) & 0xFF, value & 0xFF


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 640x480, got {text!r}") from None
    if not (16 <= width <= MAX_SIDE and 16 <= height <= MAX_SIDE):
        raise argparse.ArgumentTypeError(f"expected each side from 16 to {MAX_SIDE} pixels, got {text!r}")
    return width, height


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least 1, got {text!r}") from None
    if not 1 <= value <= 10**9:
        raise argparse.ArgumentTypeError(f"expected a whole number from 1 to 10^9, got {text!r}")
    return value


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port from 1 to 65535 (0: any free one), got {text!r}")
    return value


class Command(NamedTuple):
    """One ``puppet`` command: its help line, what adds its arguments, what runs it."""

    help: str
    arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


def _no_arguments(parser: argparse.ArgumentParser) -> None:
    """A command that takes no arguments."""


COMMANDS: dict[str, Command] = {
    "demo": Command("replay the shipped demo take on the default face to a video", _demo_arguments, _demo),
    "render": Command("render a .fap take to an MP4 video, or many takes on Dask", _render_arguments, _render),
    "play": Command("play a take (a .fap or a take folder) in a window, in real time", _play_arguments, _play),
    "replay": Command("play a take in a window; or replay its raw log through its devices' wires or another "
                      "mapping into a new .fap", _replay_arguments, _replay),
    "export": Command("export a take to glTF binary (.glb), animated by morph targets", _export_arguments, _export),
    "import-arkit": Command("import a Live Link Face / ARKit blendshape CSV as a take", _import_arkit_arguments,
                            _import_arkit),
    "lipsync": Command("make a take from a recording of speech: the mouth follows the voice, the sound kept",
                       _lipsync_arguments, _lipsync),
    "live": Command("run a mapping's devices onto the face in a window, live", _live_arguments, _live),
    "program": Command("show a served face alone on a key colour, in a window for OBS's window capture",
                       _program_arguments, _program),
    "devices": Command("list the controllers that are connected (serial, HID, MIDI, CAN, sound inputs)",
                       _no_arguments, _devices),
    "sim": Command("run a simulated controller to point the rig at: a serial joystick on a pseudo-terminal",
                   _sim_arguments, _sim),
    "mappings": Command("list the shipped mappings, or write an editable copy of one", _mappings_arguments,
                        _mappings),
    "calibrate": Command("record rest and a sweep per channel; write them into the mapping", _calibrate_arguments,
                         _calibrate),
    "bench": Command("measure Sibson precompute, rig load and per-frame deform", _bench_arguments, _bench),
    "rig": Command("rig a face mesh (its landmarks given or found) into a face folder for --face", _rig_arguments,
                   _rig),
    "calibrate-face": Command("learn how the FAPs move a face's skin from example shapes of it",
                              _calibrate_face_arguments, _calibrate_face),
    "face-from-photo": Command("build a rigged, textured face from one frontal photo", _face_from_photo_arguments,
                               _face_from_photo),
    "pick-landmarks": Command("click a photo's or a mesh's landmarks in a web page on 127.0.0.1",
                              _pick_landmarks_arguments, _pick_landmarks),
}
"""The dispatch table: ``puppet NAME`` runs ``COMMANDS[NAME].run`` (in this order in ``--help``)."""


if __name__ == "__main__":
    sys.exit(main())
