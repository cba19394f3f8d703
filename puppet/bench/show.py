"""``puppet bench --only show``: what the show server costs and how late its page is.

* ``feed``: the shipped demo take played at its own rate into the server, viewed by the page in
  headless Chromium (``puppet.bench.browser``). The delay is from a frame's publication to the page's
  echo of having drawn it (the page echoes right after its draw call; a display's compositor adds
  up to one refresh after that). Bandwidth: the feed's bytes a second against the same frames sent
  as pictures with alpha (PNG, and lossy WebP at quality 80) at the feed's size, and the CPU a
  frame costs to encode each way.
* ``clients``: the live loop's input-to-frame latency (``session.measure_latency``, the slider box
  in a process of its own) with the server publishing every frame and no client, then with four
  clients in processes of their own -- three feed viewers that take and echo every frame and one API
  client flooding messages (status, refusals) as fast as it is answered -- then with none again,
  all in one run: the ratio of the medians says what the clients cost. The clients run on the
  same machine, so on a small one their own CPU is part of it; ``server_cpu_share`` is the
  server thread's own CPU while they were there, in cores.
"""

from __future__ import annotations

import io
import json
import multiprocessing
import statistics
import time

import numpy as np

from puppet.bench.browser import HeadlessChromium, find_browser
from puppet.bench.pipeline import live_box
from puppet.live.session import measure_latency, ms_stats
from puppet.runtime.runtime import Runtime
from puppet.show.server import ShowServer
from puppet.show.stage import LiveStage
from puppet.show.wire import HEADER, FrameEncoder, Quantiser
from puppet.view.demo import demo_take
from puppet.view.renderer import Renderer
from puppet.view.rendertake import aim_at_head
from puppet.view.window import HeldTable

FEED_SIZE = (720, 720)
FLOOD = ['{"type": "status"}', '{"type": "fly"}', "not json", '{"type": "set", "channels": {"smile": 0.5}}']


def show(runtime: Runtime, seconds: float = 10.0) -> dict:
    """Both measurements: ``feed`` and ``clients``."""
    return {"feed": feed(runtime, seconds), "clients": clients(runtime, seconds)}


def feed(runtime: Runtime, seconds: float = 10.0) -> dict:
    """The page's delay and the feed's bandwidth, playing the demo take (module docstring)."""
    face = runtime.face
    table = HeldTable(demo_take(), runtime, None)
    table.ensure(10**9)
    frames = [table.mesh(k, normals=False)[0].copy() for k in range(table.count)]
    table.close()
    renderer = Renderer.for_face(face, width=FEED_SIZE[0], height=FEED_SIZE[1], transparent=True)
    aim_at_head(renderer, face, "front")
    try:
        pictures = _pictures(renderer, frames[::10])
        camera = renderer.camera
    finally:
        renderer.release()
    encode_ms = _encode_ms(frames)
    if find_browser() is None:
        return {"error": "no Chromium here", "encode_ms": encode_ms, **pictures}
    with ShowServer(face, camera, port=0, size=FEED_SIZE) as server, HeadlessChromium(FEED_SIZE) as browser:
        browser.open(server.page_url)
        server.publish(frames[0])
        browser.wait_for("window.facepuppet && window.facepuppet.drawn > 0")
        server.delays_ms.clear()
        sent = server.counts["feed_bytes"]
        start = time.monotonic()
        k = 0
        while (elapsed := time.monotonic() - start) < seconds:
            server.publish(frames[k % len(frames)])
            k += 1
            time.sleep(max(0.0, start + k / 30.0 - time.monotonic()))
        feed_bytes = server.counts["feed_bytes"] - sent
        delays = list(server.delays_ms)
    return {"frames": k, "seconds": elapsed, "delay_ms": ms_stats([round(d * 1e6) for d in delays]), "drawn": len(delays),
            "feed_kb_s": feed_bytes / elapsed / 1000, "encode_ms": encode_ms, **pictures,
            "vertices": len(face.vertices), "size": f"{FEED_SIZE[0]}x{FEED_SIZE[1]}"}


def _encode_ms(frames: list[np.ndarray]) -> float:
    """Median CPU to quantise, difference and deflate one frame for the feed."""
    encoder = FrameEncoder(Quantiser.around(frames[0]))
    times = []
    for k, vertices in enumerate(frames):
        start = time.perf_counter()
        encoder.publish(vertices, 0.0)
        encoder.message(k)
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)


def _pictures(renderer: Renderer, frames: list[np.ndarray]) -> dict:
    """What the same frames cost as pictures with alpha, 30 a second: kB/s and encode ms each."""
    from PIL import Image

    sizes: dict[str, list[int]] = {"png": [], "webp": []}
    times: dict[str, list[float]] = {"png": [], "webp": []}
    for vertices in frames:
        image = Image.fromarray(renderer.render(vertices))
        for kind, options in (("png", {}), ("webp", {"quality": 80})):
            out = io.BytesIO()
            start = time.perf_counter()
            image.save(out, format=kind.upper(), **options)
            times[kind].append((time.perf_counter() - start) * 1e3)
            sizes[kind].append(out.tell())
    return {f"{kind}_kb_s": statistics.mean(sizes[kind]) * 30 / 1000 for kind in sizes} | {
        f"{kind}_encode_ms": statistics.median(times[kind]) for kind in times}


def clients(runtime: Runtime, seconds: float = 10.0) -> dict:
    """The live loop's latency with 0, then 4, then 0 clients (module docstring)."""
    spawn = multiprocessing.get_context("spawn")
    with live_box(runtime, (640, 480)) as (session, renderer):
        from puppet.show.serving import FEED_SIZE as SIZE
        from puppet.view.renderer import aim_camera
        from puppet.view.rendertake import head_points

        camera = aim_camera(head_points(runtime.face), SIZE)
        with ShowServer(runtime.face, camera, port=0, size=SIZE, stage=LiveStage(session)) as server:
            alone = measure_latency(session, renderer, seconds, outputs=[server])
            stop, answered = spawn.Event(), spawn.Value("q", 0)
            base = f"ws://127.0.0.1:{server.port}"
            workers = [spawn.Process(target=view_feed, args=(f"{base}/feed?token={server.token}", stop), daemon=True)
                       for _ in range(3)]
            workers.append(spawn.Process(target=flood_api, args=(f"{base}/api?token={server.token}", stop, answered),
                                         daemon=True))
            for worker in workers:
                worker.start()
            _wait_until(lambda: server.viewers == 3 and answered.value > 0)
            refused, cpu = server.counts["refused"], server.thread_cpu()
            crowded = measure_latency(session, renderer, seconds, outputs=[server])
            cpu = server.thread_cpu() - cpu
            flood = answered.value
            stop.set()
            for worker in workers:
                worker.join(10)
            refused = server.counts["refused"] - refused
            again = measure_latency(session, renderer, seconds, outputs=[server])
    runs = {"no_clients": alone, "four_clients": crowded, "no_clients_again": again}
    drawn = {name: run["sample_to_drawn_ms"]["median"] for name, run in runs.items()}
    summary = {name: {"sample_to_drawn_ms": run["sample_to_drawn_ms"], "fps": run["fps"]} for name, run in runs.items()}
    return summary | {
        "ratio": drawn["four_clients"] / statistics.mean([drawn["no_clients"], drawn["no_clients_again"]]),
        "api_answers_s": flood / seconds, "api_refused": refused, "seconds": seconds,
        "server_cpu_share": cpu / seconds}


def _wait_until(condition, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise RuntimeError("the show's bench clients did not connect")
        time.sleep(0.05)


def view_feed(url: str, stop) -> None:
    """A feed viewer in a process of its own: takes every frame and echoes it, as a page does
    after drawing it, until ``stop`` (it does not decode: a page's drawing is the browser's CPU,
    elsewhere or not, and the point is what the server costs the loop)."""
    from websockets.sync.client import connect

    with connect(url, max_size=None) as ws:
        ws.recv()
        while not stop.is_set():
            try:
                message = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            _, number, published = HEADER.unpack_from(message)
            ws.send(json.dumps({"drawn": number, "published": published}))


def flood_api(url: str, stop, answered) -> None:
    """An API client in a process of its own, sending as fast as it is answered, until ``stop``."""
    from websockets.sync.client import connect

    with connect(url) as ws:
        k = 0
        while not stop.is_set():
            ws.send(FLOOD[k % len(FLOOD)])
            ws.recv(timeout=5)
            k += 1
            with answered.get_lock():
                answered.value += 1
