"""The show server for ``puppet live --serve`` and ``puppet play --serve``: made, started, said.

``serve_live`` gives a live session's server (its stage: the session, ``LiveStage``);
``serve_playback`` a take's (nothing to drive). Each prints the page's address with its token, and
the control API's, on stderr, and is closed with the loop that publishes to it.
"""

from __future__ import annotations

import sys
from typing import Any

from puppet.show.server import ShowServer
from puppet.show.stage import LiveStage, Stage
from puppet.view.renderer import aim_camera
from puppet.view.rendertake import head_points

FEED_SIZE = (720, 720)
"""The size the feed's camera frames the head for; a page of another shape keeps its height."""


def serve_live(session: Any, address: tuple[str, int], view: str = "front",
               osc: tuple[str, int] | None = None) -> ShowServer:
    """The started server of a live session's face; its control API drives the session (and
    OSC control addresses on ``osc``, a UDP address, when given)."""
    return _started(session.runtime.face, address, view, LiveStage(session), osc)


def serve_playback(face: Any, address: tuple[str, int], view: str = "front") -> ShowServer:
    """The started server of a take being played."""
    return _started(face, address, view, Stage())


def _started(face: Any, address: tuple[str, int], view: str, stage: Stage,
             osc: tuple[str, int] | None = None) -> ShowServer:
    camera = aim_camera(head_points(face), FEED_SIZE, view)
    server = ShowServer(face, camera, host=address[0], port=address[1], size=FEED_SIZE, stage=stage, osc=osc).start()
    base = server.page_url.split("/?", 1)[0]
    print(f"program feed: {server.page_url}  (OBS: Browser Source with this URL)", file=sys.stderr)
    print(f"control API: {base.replace('http', 'ws', 1)}/api?token={server.token}", file=sys.stderr)
    if server.osc_address is not None:
        print(f"OSC control: udp {server.osc_address[0]}:{server.osc_address[1]} (/puppet/set, /puppet/trigger, "
              "/puppet/record, /puppet/neutral)", file=sys.stderr)
    return server
