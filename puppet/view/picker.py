"""A landmark picker for people without a detector: a web page on loopback showing the photo,
where the user clicks the points in order; saved as the landmark JSON ``puppet.photo.build``
reads (``{"layout": ..., "points": [[x, y], ...]}``, pixels of the full-size photo).

``PickerServer`` serves the page (``http.server`` in a thread, 127.0.0.1 only, a free port):
``GET /`` the page, ``GET /photo`` the photo, ``POST /points`` the clicked points, which it
checks (count, inside the image), writes, and then stops. The page lists the point to click
next with a hint, has Undo and Save. Nothing but these three paths is served.
"""

from __future__ import annotations

import html
import json
import mimetypes
import os
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from puppet.photo.build import FDP11, FDP11_HINTS, PhotoFaceError, check_inside, parse_landmarks, read_photo

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
}

_PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>facepuppet landmarks</title>
<style>body{font-family:sans-serif;margin:1em} #wrap{position:relative;display:inline-block}
img{max-width:90vw;max-height:80vh;cursor:crosshair} .dot{position:absolute;width:8px;height:8px;
margin:-4px;border-radius:4px;background:#f33;pointer-events:none}</style></head><body>
<p>Click, in order: <b id="next"></b> (<span id="count"></span>)
<button id="undo">Undo</button> <button id="save" disabled>Save</button> <span id="msg"></span></p>
<div id="wrap"><img id="photo" src="/photo" alt="photo"></div>
<script>
const hints = HINTS, layout = LAYOUT, pts = [];
const img = document.getElementById('photo'), wrap = document.getElementById('wrap');
function show() {
  wrap.querySelectorAll('.dot').forEach(d => d.remove());
  for (const [x, y] of pts) {
    const d = document.createElement('div'); d.className = 'dot';
    d.style.left = (x * img.clientWidth / img.naturalWidth) + 'px';
    d.style.top = (y * img.clientHeight / img.naturalHeight) + 'px'; wrap.appendChild(d);
  }
  document.getElementById('next').textContent = pts.length < hints.length ? hints[pts.length] : 'done';
  document.getElementById('count').textContent = pts.length + ' of ' + hints.length;
  document.getElementById('save').disabled = pts.length !== hints.length;
}
img.addEventListener('click', e => {
  if (pts.length >= hints.length) return;
  pts.push([e.offsetX * img.naturalWidth / img.clientWidth, e.offsetY * img.naturalHeight / img.clientHeight]);
  show();
});
document.getElementById('undo').onclick = () => { pts.pop(); show(); };
document.getElementById('save').onclick = async () => {
  const r = await fetch('/points', {method: 'POST', headers: {'Content-Type': 'application/json'},
                                    body: JSON.stringify({layout: layout, points: pts})});
  document.getElementById('msg').textContent = await r.text();
};
img.onload = show;
</script></body></html>"""


class PickerServer:
    """The picker's loopback web server for one photo; ``wait`` returns the saved file."""

    def __init__(self, photo: str | os.PathLike, layout: str, out: str | os.PathLike, port: int = 0) -> None:
        if layout not in LAYOUT_HINTS:
            raise PhotoFaceError(f"the picker knows layouts {sorted(LAYOUT_HINTS)}, not {layout!r}")
        self.photo, self.layout, self.out = Path(photo), layout, Path(out)
        image = read_photo(self.photo)
        self.size = (image.shape[1], image.shape[0])
        self.saved = threading.Event()
        self._server = ThreadingHTTPServer(("127.0.0.1", port), _handler(self))
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}/"

    def page(self) -> bytes:
        """The page, with this layout's hints."""
        hints = json.dumps(LAYOUT_HINTS[self.layout])
        return _PAGE.replace("HINTS", hints).replace("LAYOUT", json.dumps(self.layout)).encode("utf-8")

    def save(self, body: bytes) -> str:
        """Check and write POSTed points; raises ``PhotoFaceError`` with what is wrong."""
        try:
            data = json.loads(body)
        except json.JSONDecodeError as exc:
            raise PhotoFaceError(f"not JSON: {exc}") from None
        data = {"layout": self.layout, "points": data.get("points") if isinstance(data, dict) else data}
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
            else:
                self._reply(404, b"not found", "text/plain")

        def do_POST(self) -> None:
            if self.path != "/points":
                self._reply(404, b"not found", "text/plain")
                return
            body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
            try:
                self._reply(200, picker.save(body).encode(), "text/plain; charset=utf-8")
            except PhotoFaceError as exc:
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
