"""The show server: the program feed's frames, the control API's messages, and both over real
WebSockets against a live session; the page itself in a real browser is in test_show_browser."""

from __future__ import annotations

import contextlib
import json
import socket
import threading
import time
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pythonosc.udp_client import SimpleUDPClient
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from puppet.face.load import load_face
from puppet.io.fapfile import iter_fap
from puppet.show import api, osccontrol
from puppet.show.server import ShowServer
from puppet.show.stage import LiveStage
from puppet.show.wire import DELTA, KEY, TOP, FrameEncoder, Quantiser, decode
from puppet.view.liveoutput import HeadlessLive
from puppet.view.livewindow import LiveStats, open_session
from puppet.view.renderer import aim_camera
from puppet.view.rendertake import head_points

API_MAPPING = """
devices:
  api: {url: "api://"}
channels:
  api.smile: {}
  api.wow: {}
targets:
  - {expression: joy, source: api.smile}
triggers:
  wow: {source: api.wow, mode: oneshot, expression: surprise, attack: 0.05, hold: 0.2, release: 0.05}
idle: false   # the feed's first frame is compared with the face at rest (idle life: tests/test_idlelife.py)
"""


# -- frames on the wire ---------------------------------------------------------------------------

@settings(max_examples=60, deadline=None)
@given(st.data())
def test_frames_decode_to_within_half_a_step_whichever_frames_a_client_misses(data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    rest = rng.normal(size=(30, 3))
    quantiser = Quantiser.around(rest)
    encoder = FrameEncoder(quantiser)
    codes, after = None, 0
    for _ in range(data.draw(st.integers(1, 8))):
        moved = rest + rng.normal(scale=data.draw(st.sampled_from([0.0, 0.01, 0.5])), size=rest.shape)
        encoder.publish(moved, time.monotonic())
        if data.draw(st.booleans()):  # this client misses the frame
            continue
        kind, number, _, codes = decode(encoder.message(after), codes)
        assert kind == (DELTA if after == number - 1 and after > 0 else KEY)
        after = number
        inside = np.clip(moved, quantiser.origin, quantiser.origin + TOP * quantiser.step)
        assert np.all(np.abs(quantiser.positions(codes) - inside) <= quantiser.step / 2 + 1e-12)


def test_a_still_face_costs_next_to_nothing_per_frame():
    face = load_face()
    encoder = FrameEncoder(Quantiser.around(face.vertices))
    encoder.publish(face.vertices, 0.0)
    key = encoder.message(0)
    encoder.publish(face.vertices, 0.0)
    still = encoder.message(1)
    assert len(still) < 400 < 30_000 < len(key) < face.vertices.size * 2


# -- the API's messages ------------------------------------------------------------------------

NAMES = st.text(min_size=0, max_size=70)
VALUES = st.one_of(st.none(), st.booleans(), st.integers(-2**60, 2**60),
                   st.floats(allow_nan=False, allow_infinity=False), NAMES, st.lists(st.integers(), max_size=2),
                   st.dictionaries(NAMES, st.floats(allow_nan=False), max_size=3))
MESSAGES = st.fixed_dictionaries(
    {"type": st.one_of(st.sampled_from(api.TYPES), VALUES)},
    optional={"id": VALUES, "interval": VALUES, "name": VALUES, "action": st.one_of(
                  st.sampled_from(api.TRIGGER_ACTIONS + api.RECORD_ACTIONS), VALUES),
              "device": VALUES, "extra": VALUES,
              "channels": st.one_of(VALUES, st.dictionaries(NAMES, st.one_of(st.floats(allow_nan=False), VALUES),
                                                            max_size=4))})
SCHEMA = jsonschema.Draft202012Validator(api.schema())


@settings(max_examples=3000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(MESSAGES)
def test_the_api_accepts_exactly_the_messages_its_schema_allows(message):
    valid = SCHEMA.is_valid(message)
    try:
        api.check(message)
    except api.ApiError as refusal:
        assert not valid, f"refused a message the schema allows: {refusal}"
        assert str(refusal)
    else:
        assert valid, f"accepted a message the schema refuses: {message}"


@settings(max_examples=2000, deadline=None)
@given(st.one_of(st.text(max_size=200), st.binary(max_size=200), MESSAGES.map(json.dumps)))
def test_any_text_is_a_checked_message_or_refused_with_a_reason(text):
    try:
        message = api.parse(text)
    except api.ApiError as refusal:
        assert str(refusal)
    else:
        assert SCHEMA.is_valid(message)


def test_what_json_allows_but_a_number_is_not_is_refused():
    for text in ('{"type": "set", "channels": {"a": NaN}}', '{"type": "subscribe", "interval": Infinity}'):
        with pytest.raises(api.ApiError, match="not a number JSON allows"):
            api.parse(text)
    with pytest.raises(api.ApiError, match="longer than"):
        api.parse('{"type": "status", "id": "' + "x" * api.MAX_MESSAGE + '"}')
    with pytest.raises(api.ApiError, match="not JSON"):
        api.parse("[" * 60_000)  # nested past the recursion limit, within the size


# -- over WebSockets, against a live session ----------------------------------------------------

class Loop:
    """A live session's loop without a window (``HeadlessLive``) in a thread, serving ``server``."""

    def __init__(self, session, server) -> None:
        self.live = HeadlessLive(session, [server], LiveStats())
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.live.step()
            time.sleep(0.01)

    def close(self) -> None:
        self._stop.set()
        self.thread.join(5)


@pytest.fixture(scope="module")
def face():
    return load_face()


@contextlib.contextmanager
def live_show(folder: Path, face, take: str = "api", osc: tuple[str, int] | None = None):
    """(server, session): the API mapping's live session, served, its loop running."""
    mapping = folder / "api.yaml"
    mapping.write_text(API_MAPPING)
    session = open_session(mapping, record=take, record_root=folder / "takes", face=face)
    camera = aim_camera(head_points(face), (320, 320))
    server = ShowServer(face, camera, port=0, size=(320, 320), stage=LiveStage(session), osc=osc).start()
    loop = Loop(session, server)
    try:
        assert _wait(lambda: "devices" in server.status)  # the loop's first frame is out
        yield server, session
    finally:
        loop.close()
        server.close()
        session.close()


@pytest.fixture
def show(tmp_path, face):
    with live_show(tmp_path, face) as served:
        yield served


def _ask(ws, **message) -> dict:
    ws.send(json.dumps(message))
    while True:
        reply = json.loads(ws.recv(timeout=5))
        if reply.get("type") != "status":
            return reply


def test_sockets_need_the_token_and_this_origin(show):
    server, _ = show
    base = f"ws://127.0.0.1:{server.port}"
    for path in ("/api", "/feed", "/api?token=wrong"):
        with pytest.raises(InvalidStatus) as refused:
            connect(base + path)
        assert refused.value.response.status_code == 403
    with pytest.raises(InvalidStatus):
        connect(f"{base}/api?token={server.token}", origin="http://evil.example")
    with connect(f"{base}/api?token={server.token}") as ws:
        assert _ask(ws, type="status", id=1)["ok"]


def test_a_script_sets_channels_fires_a_take_and_lists_it(show):
    server, session = show
    with connect(f"ws://127.0.0.1:{server.port}/api?token={server.token}") as ws:
        status = _ask(ws, type="status", id="s")
        assert status["id"] == "s" and status["status"]["devices"] == {"api": "open"}
        started = _ask(ws, type="record", action="start", id=2)
        assert started["ok"] and Path(started["take"]).name == "api_001"
        assert not _ask(ws, type="record", action="start")["ok"]  # already recording
        assert _ask(ws, type="set", channels={"smile": 1.0})["ok"]
        time.sleep(0.3)
        _ask(ws, type="set", channels={"smile": 0.0})
        time.sleep(0.2)
        stopped = _ask(ws, type="record", action="stop")
        assert stopped["ok"] and stopped["take"] == started["take"]
        takes = _ask(ws, type="takes")["takes"]
        assert [t["name"] for t in takes] == ["api_001"] and takes[0]["complete"]
    with iter_fap(Path(started["take"]) / "take.fap") as reader:
        joy = [f.expression[1] if f.expression[0] == 1 else 0 for f in reader]
    assert max(joy) == 63 and joy[-1] == 0  # the script's smile, full, then gone


def test_a_stream_deck_fires_a_trigger_by_name_and_the_take_keeps_it(show):
    server, session = show
    with connect(f"ws://127.0.0.1:{server.port}/api?token={server.token}") as ws:
        started = _ask(ws, type="record", action="start")
        assert _ask(ws, type="trigger", name="wow") == {"id": None, "ok": True, "name": "wow", "action": "fire"}
        assert _wait(lambda: server.status.get("triggers", {}).get("wow", 0) > 0)
        time.sleep(0.5)
        _ask(ws, type="record", action="stop")
    with iter_fap(Path(started["take"]) / "take.fap") as reader:
        surprise = [f.expression[1] if f.expression[0] == 6 else 0 for f in reader]
    assert max(surprise) > 60 and surprise[-1] == 0  # up, held, and back to rest


def test_refusals_say_why_and_the_connection_goes_on(show):
    server, _ = show
    with connect(f"ws://127.0.0.1:{server.port}/api?token={server.token}") as ws:
        for message, reason in [("nonsense", "not JSON"), ('{"type": "fly"}', "expected one of"),
                                ('{"type": "set", "channels": {"frown": 1}}', None),
                                ('{"type": "trigger", "name": "wave"}', "no trigger 'wave': expected one of wow"),
                                ('{"type": "record", "action": "stop"}', "not recording")]:
            ws.send(message)
            reply = json.loads(ws.recv(timeout=5))
            assert reply["ok"] is (reason is None), reply
            assert reason is None or reason in reply["error"]
        assert _ask(ws, type="status")["ok"]
    assert server.counts["refused"] >= 4


def test_an_oversized_message_closes_only_its_own_connection(show):
    server, _ = show
    url = f"ws://127.0.0.1:{server.port}/api?token={server.token}"
    with connect(url) as other, connect(url, max_size=None) as flooder:
        with pytest.raises(ConnectionClosed) as closed:
            flooder.send("x" * (api.MAX_MESSAGE + 1))
            flooder.recv(timeout=5)
        assert closed.value.rcvd.code == 1009
        assert _ask(other, type="status")["ok"]


def test_a_client_gone_mid_message_changes_nothing(show):
    server, session = show
    raw = socket.create_connection(("127.0.0.1", server.port))
    raw.sendall(f"GET /api?token={server.token} HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nUpgrade: websocket\r\n"
                "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                "Sec-WebSocket-Version: 13\r\n\r\n".encode())
    assert b"101" in raw.recv(1024)
    raw.sendall(bytes([0x81, 0xFE, 0x01, 0x00]) + b"\x00\x00\x00\x00" + b'{"type": "rec')  # 256 announced
    raw.close()
    frames = session.frames
    with connect(f"ws://127.0.0.1:{server.port}/api?token={server.token}") as ws:
        assert _ask(ws, type="status")["ok"]
    assert _wait(lambda: session.frames > frames + 5) and not session.recording


def test_the_feed_sends_the_face_then_frames_and_hears_each_drawn(show, face):
    server, _ = show
    with connect(f"ws://127.0.0.1:{server.port}/feed?token={server.token}", max_size=None) as ws:
        first = json.loads(ws.recv(timeout=5))
        assert first["type"] == "face" and first["n_vertices"] == len(face.vertices)
        assert all("#version 300 es" in text for pair in first["shaders"].values() for text in pair)
        kind, number, published, codes = decode(ws.recv(timeout=5), None)
        assert kind == KEY
        positions = Quantiser(np.array(first["origin"]), np.array(first["step"])).positions(codes)
        assert np.abs(positions - face.vertices).max() < 1e-4 * np.ptp(face.vertices)
        ws.send(json.dumps({"drawn": number, "published": published}))
        assert _wait(lambda: len(server.delays_ms) > 0)
        assert server.viewers == 1


def _wait(condition, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return False




# -- OSC control ------------------------------------------------------------------------------

@pytest.mark.parametrize("address, arguments, message", [
    ("/puppet/set/smile", [0.5], {"type": "set", "channels": {"smile": 0.5}}),
    ("/puppet/set", ["smile", 1, "brow", 0.25], {"type": "set", "channels": {"smile": 1, "brow": 0.25}}),
    ("/puppet/trigger/wave", [], {"type": "trigger", "name": "wave", "action": "fire"}),
    ("/puppet/trigger/wave", [1], {"type": "trigger", "name": "wave", "action": "press"}),
    ("/puppet/trigger/wave", [0.0], {"type": "trigger", "name": "wave", "action": "release"}),
    ("/puppet/record/start", [], {"type": "record", "action": "start"}),
    ("/puppet/record", [0], {"type": "record", "action": "stop"}),
    ("/puppet/neutral", [], {"type": "neutral"}),
])
def test_osc_addresses_stand_for_api_messages(address, arguments, message):
    assert osccontrol.api_message(address, arguments) == message


@pytest.mark.parametrize("address, arguments, reason", [
    ("/other/set", [1], "start with /puppet/"), ("/puppet/set/smile", ["lots"], "one number"),
    ("/puppet/set", ["smile"], "pairs"), ("/puppet/trigger/wave", ["wiggle"], "action"),
    ("/puppet/record/pause", [], "action"), ("/puppet/fly", [], "expected /puppet/set"),
])
def test_osc_messages_that_stand_for_nothing_say_why(address, arguments, reason):
    with pytest.raises(api.ApiError, match=reason):
        osccontrol.api_message(address, arguments)


def test_a_lighting_desk_starts_a_take_over_osc(tmp_path, face):
    with live_show(tmp_path, face, "desk", osc=("127.0.0.1", 0)) as (server, session):
        desk = SimpleUDPClient(*server.osc_address)
        desk.send_message("/puppet/set/smile", 1.0)
        desk.send_message("/puppet/record/start", [])
        assert _wait(lambda: session.recording)
        desk.send_message("/puppet/record", 0)
        assert _wait(lambda: not session.recording)
        desk.send_message("/puppet/fly", [])
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.sendto(b"\xff" * 13, server.osc_address)  # not OSC at all
        assert _wait(lambda: server.osc.counts["refused"] == 2)
        assert (tmp_path / "takes" / "desk_001" / "take.fap").exists()


def test_a_stream_of_mangled_messages_is_answered_one_by_one_and_the_loop_goes_on(show):
    server, session = show
    rng = np.random.default_rng(7)
    seeds = ['{"type": "status", "id": 1}', '{"type": "set", "channels": {"smile": 0.8}}',
             '{"type": "trigger", "name": "wow", "action": "press"}', '{"type": "takes"}', '{"type": "neutral"}']
    frames = session.frames
    with connect(f"ws://127.0.0.1:{server.port}/api?token={server.token}") as ws:
        answers = []
        for k in range(300):
            text = list(seeds[k % len(seeds)])
            for _ in range(rng.integers(0, 3)):
                text[rng.integers(len(text))] = chr(rng.integers(0, 0x3000))
            ws.send("".join(text[:rng.integers(len(text) // 2, len(text) + 1)]))
            answers.append(json.loads(ws.recv(timeout=5)))
    assert all(isinstance(a["ok"], bool) and (a["ok"] or a["error"]) for a in answers)
    assert 0 < sum(a["ok"] for a in answers) < 300
    assert _wait(lambda: session.frames > frames + 10)


def test_a_subscriber_hears_status_on_its_interval_and_at_once_when_a_take_starts(show):
    server, _ = show
    url = f"ws://127.0.0.1:{server.port}/api?token={server.token}"
    with connect(url) as watcher, connect(url) as script:
        watcher.send(json.dumps({"type": "subscribe", "interval": 1.0, "id": "w"}))
        events = []
        while len(events) < 1:
            message = json.loads(watcher.recv(timeout=5))
            if message.get("type") == "status":
                events.append(message)
        assert {"devices", "fps", "latency_ms", "recording", "frames", "triggers"} <= set(events[0]["status"])
        _ask(script, type="record", action="start")
        started = time.monotonic()
        while True:  # the change is told before the next tick of the interval
            message = json.loads(watcher.recv(timeout=5))
            if message.get("type") == "status" and message["status"]["recording"]:
                break
        assert time.monotonic() - started < 0.9
        _ask(script, type="record", action="stop")


def test_the_guide_s_python_client_runs_against_a_live_rig(show, monkeypatch, capsys):
    server, _ = show
    guide = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "show.md").read_text("utf-8")
    example = guide.split("```python\n", 1)[1].split("```", 1)[0]
    example = example.replace("8765", str(server.port)).replace("PASTE-THE-TOKEN", server.token)
    exec(compile(example, "docs/guide/show.md", "exec"), {})
    printed = capsys.readouterr().out
    assert "'ok': True" in printed and "api_001" in printed
