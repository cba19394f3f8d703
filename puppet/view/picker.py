"""A landmark picker: a web page on loopback showing the photo, where the user clicks the points
in order (``fdp11``, ``ibug68``) or drags detected ones into place (``mediapipe468``); saved as
the landmark JSON ``puppet.photo.build`` reads (``{"layout": ..., "points": [[x, y], ...]}``,
pixels of the full-size photo; MediaPipe points keep their depth).

The page draws the photo on a canvas that zooms (mouse wheel, about the pointer; + and - keys;
0 fits the photo) and pans (drag the photo), so points a couple of pixels apart on a small face
can be told apart. A click that does not drag places the next point; a press on a point drags
it (any layout: a clicked point can be nudged); Undo takes the last clicked point back.

``PickerServer`` serves the page (``http.server`` in a thread, 127.0.0.1 only, a free port):
``GET /`` the page, ``GET /photo`` the photo, ``GET /start`` the points to start from (the
detected MediaPipe points; none for the click layouts), ``POST /points`` the points, which it
checks (count, inside the image), writes, and then stops. Nothing but these paths is served.
"""

from __future__ import annotations

import html
import json
import mimetypes
import os
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np

from puppet.errors import PuppetError
from puppet.photo.build import (
    FDP11,
    FDP11_HINTS,
    MEDIAPIPE_FDP,
    PhotoFaceError,
    check_inside,
    parse_landmarks,
    read_photo,
)

IBUG_PARTS = [(0, 17, "jaw line, from the photo's left ear level down round the chin to the right"),
              (17, 22, "brow on the photo's left, outer to inner"), (22, 27, "brow on the photo's right, inner to outer"),
              (27, 31, "nose bridge, top to tip"), (31, 36, "nose bottom, photo's left to right"),
              (36, 42, "eye on the photo's left: outer corner, upper lid x2, inner corner, lower lid x2"),
              (42, 48, "eye on the photo's right: inner corner, upper lid x2, outer corner, lower lid x2"),
              (48, 60, "outer lips clockwise from the photo's left corner"),
              (60, 68, "inner lips clockwise from the photo's left corner")]
LAYOUT_HINTS = {
    "fdp11": [f"{fid}: {FDP11_HINTS[fid]}" for fid in FDP11],
    "ibug68": [f"{i}: {text}" for lo, hi, text in IBUG_PARTS for i in range(lo, hi)],
    "mediapipe468": [("drag any point that is off the face's feature into place (the larger dots are the "
                      "MPEG-4 feature points: eye corners and lids, brows, nose, lips, chin)")],
}
DRAGGED = ("mediapipe468",)  # layouts whose points come detected and are only dragged

_PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>facepuppet landmarks</title>
<style>body{font-family:sans-serif;margin:1em} canvas{border:1px solid #999;cursor:crosshair;
touch-action:none}</style></head><body>
<p><b id="next"></b> (<span id="count"></span>)
<button id="undo">Undo</button> <button id="fit">Fit</button> <button id="save" disabled>Save</button>
<span id="msg"></span><br><small>wheel or +/-: zoom about the pointer; drag the photo: pan; drag a point:
move it; 0: fit</small></p>
<canvas id="view" width="960" height="720"></canvas>
<script>
const hints = HINTS, layout = LAYOUT, dragged = DRAGGED, keys = KEYS, labels = LABELS;
let pts = [], moving = -1, press = null, scale = 1, ox = 0, oy = 0;
const canvas = document.getElementById('view'), ctx = canvas.getContext('2d'), img = new Image();
const total = () => dragged ? pts.length : hints.length;
function fit() {
  scale = Math.min(canvas.width / img.naturalWidth, canvas.height / img.naturalHeight);
  ox = (canvas.width - img.naturalWidth * scale) / 2; oy = (canvas.height - img.naturalHeight * scale) / 2; draw();
}
function toPhoto(e) {
  const r = canvas.getBoundingClientRect();
  const cx = (e.clientX - r.left) * canvas.width / r.width, cy = (e.clientY - r.top) * canvas.height / r.height;
  return [cx, cy, (cx - ox) / scale, (cy - oy) / scale];
}
function nearest(cx, cy) {
  let best = -1, dist = 8;
  pts.forEach(([x, y], i) => { const d = Math.hypot(x * scale + ox - cx, y * scale + oy - cy);
                               if (d < dist) { dist = d; best = i; } });
  return best;
}
function draw() {
  ctx.setTransform(1, 0, 0, 1, 0, 0); ctx.fillStyle = '#444'; ctx.fillRect(0, 0, canvas.width, canvas.height);
  ctx.imageSmoothingEnabled = scale < 4; ctx.setTransform(scale, 0, 0, scale, ox, oy); ctx.drawImage(img, 0, 0);
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  pts.forEach(([x, y], i) => { const big = keys.includes(i); ctx.fillStyle = big ? '#ff3' : '#f33';
    ctx.beginPath(); ctx.arc(x * scale + ox, y * scale + oy, big ? 3.5 : 2, 0, 7); ctx.fill();
    if (labels.length) { ctx.font = '11px sans-serif';
                         ctx.fillText(labels[i], x * scale + ox + 5, y * scale + oy - 4); } });
  document.getElementById('next').textContent = dragged ? hints[0] :
    (pts.length < hints.length ? 'Click, in order: ' + hints[pts.length] : 'done');
  document.getElementById('count').textContent = pts.length + ' of ' + total();
  document.getElementById('save').disabled = pts.length !== total() || total() === 0;
}
function zoom(factor, cx, cy) {
  const s = Math.min(64, Math.max(0.05, scale * factor));
  ox = cx - (cx - ox) * s / scale; oy = cy - (cy - oy) * s / scale; scale = s; draw();
}
canvas.addEventListener('wheel', e => { e.preventDefault(); const [cx, cy] = toPhoto(e);
  zoom(e.deltaY < 0 ? 1.25 : 0.8, cx, cy); }, {passive: false});
canvas.addEventListener('pointerdown', e => { const [cx, cy] = toPhoto(e);
  moving = nearest(cx, cy); press = {cx, cy, ox, oy, moved: false}; canvas.setPointerCapture(e.pointerId); });
canvas.addEventListener('pointermove', e => { if (!press) return; const [cx, cy, x, y] = toPhoto(e);
  if (Math.hypot(cx - press.cx, cy - press.cy) > 3) press.moved = true;
  if (!press.moved) return;
  if (moving >= 0) pts[moving] = [x, y, ...pts[moving].slice(2)];
  else { ox = press.ox + cx - press.cx; oy = press.oy + cy - press.cy; }
  draw(); });
canvas.addEventListener('pointerup', e => { const [, , x, y] = toPhoto(e);
  if (press && !press.moved && moving < 0 && !dragged && pts.length < hints.length) pts.push([x, y]);
  press = null; moving = -1; draw(); });
document.addEventListener('keydown', e => {
  const c = [canvas.width / 2, canvas.height / 2];
  if (e.key === '+' || e.key === '=') zoom(1.25, ...c); else if (e.key === '-') zoom(0.8, ...c);
  else if (e.key === '0') fit(); });
document.getElementById('fit').onclick = fit;
document.getElementById('undo').onclick = () => { if (!dragged) { pts.pop(); draw(); } };
document.getElementById('save').onclick = async () => {
  const r = await fetch('/points', {method: 'POST', headers: {'Content-Type': 'application/json'},
                                    body: JSON.stringify({layout: layout, points: pts})});
  document.getElementById('msg').textContent = await r.text();
};
img.onload = async () => { pts = (await (await fetch('/start')).json()).points; fit(); };
img.src = '/photo';
</script></body></html>"""


class PickerServer:
    """The picker's loopback web server for one photo; ``wait`` returns the saved file.
    ``start`` is the landmark JSON to begin from: required for ``mediapipe468`` (the detected
    points, ``puppet.photo.detect``), none for the click layouts."""

    def __init__(self, photo: str | os.PathLike, layout: str, out: str | os.PathLike, port: int = 0,
                 start: dict | None = None) -> None:
        if layout not in LAYOUT_HINTS:
            raise PhotoFaceError(f"the picker knows layouts {sorted(LAYOUT_HINTS)}, not {layout!r}")
        self.photo, self.layout, self.out = Path(photo), layout, Path(out)
        image = read_photo(self.photo)
        self.size = (image.shape[1], image.shape[0])
        self.start = self._start(start)
        self.hints, self.dragged, self.labels = LAYOUT_HINTS[layout], layout in DRAGGED, []
        self._serve(port)

    def _serve(self, port: int) -> None:
        """Start serving the page on 127.0.0.1:``port`` (0: a free one) in a thread."""
        self.saved = threading.Event()
        self._server = ThreadingHTTPServer(("127.0.0.1", port), _handler(self))
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)
        self._thread.start()

    def _start(self, start: dict | None) -> list[list[float]]:
        if self.layout not in DRAGGED:
            return []
        if start is None:
            raise PhotoFaceError(f"layout {self.layout}: the picker moves detected points; give them (--start) "
                                 "or set up the photo environment to detect them")
        landmarks = parse_landmarks(start, "the points to start from")
        if landmarks.layout != self.layout:
            raise PhotoFaceError(f"the points to start from are layout {landmarks.layout}, not {self.layout}")
        check_inside(landmarks, self.size)
        columns = [landmarks.points] + ([landmarks.depth[:, None]] if landmarks.depth is not None else [])
        return np.hstack(columns).tolist()

    @property
    def url(self) -> str:
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}/"

    def page(self) -> bytes:
        """The page, with this layout's hints, (for MediaPipe) its feature points drawn large and
        the points' ``labels`` (none for a photo) drawn beside them."""
        keys = sorted(MEDIAPIPE_FDP) if self.layout == "mediapipe468" else list(range(len(self.labels)))
        fills = {"HINTS": json.dumps(self.hints), "LAYOUT": json.dumps(self.layout),
                 "DRAGGED": json.dumps(self.dragged), "KEYS": json.dumps(keys),
                 "LABELS": json.dumps(self.labels)}
        page = _PAGE
        for name, value in fills.items():
            page = page.replace(name, value)
        return page.encode("utf-8")

    def save(self, body: bytes) -> str:
        """Check and write POSTed points; raises ``PhotoFaceError`` with what is wrong. Dragged
        points keep the depth they started with."""
        try:
            data = json.loads(body)
        except json.JSONDecodeError as exc:
            raise PhotoFaceError(f"not JSON: {exc}") from None
        points = data.get("points") if isinstance(data, dict) else data
        if self.start and isinstance(points, list) and len(points) == len(self.start):
            points = [list(p[:2]) + list(s[2:]) if isinstance(p, list) else p for p, s in zip(points, self.start)]
        data = {"layout": self.layout, "points": points}
        check_inside(parse_landmarks(data, "the clicked points"), self.size)
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.out.write_text(json.dumps(data, indent=1), encoding="utf-8")
        self.saved.set()
        return f"saved {len(data['points'])} points to {self.out}"

    def wait(self, timeout: float | None = None) -> Path | None:
        """Block until the points are saved (then stop serving); the file, or None on timeout."""
        done = self.saved.wait(timeout)
        self.close()
        return self.out if done else None

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()


def _handler(picker: PickerServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            if self.path == "/":
                self._reply(200, picker.page(), "text/html; charset=utf-8")
            elif self.path == "/photo":
                kind = mimetypes.guess_type(picker.photo.name)[0] or "application/octet-stream"
                self._reply(200, picker.photo.read_bytes(), kind)
            elif self.path == "/start":
                body = json.dumps({"layout": picker.layout, "points": picker.start}).encode()
                self._reply(200, body, "application/json")
            else:
                self._reply(404, b"not found", "text/plain")

        def do_POST(self) -> None:
            if self.path != "/points":
                self._reply(404, b"not found", "text/plain")
                return
            body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
            try:
                self._reply(200, picker.save(body).encode(), "text/plain; charset=utf-8")
            except PuppetError as exc:  # PhotoFaceError (a photo's points), LandmarkError (a mesh's)
                self._reply(400, html.escape(str(exc)).encode(), "text/plain; charset=utf-8")

        def _reply(self, status: int, body: bytes, kind: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args) -> None:  # quiet: the terminal shows the URL only
            pass

    return Handler
