"""The show: the face and its controls reached from outside the window.

``puppet live --serve HOST:PORT`` (and ``puppet play --serve``) starts a ``ShowServer``: a page
that OBS's Browser Source (or any browser) shows as the face alone on a transparent background,
following the performance, and a WebSocket JSON control API on the same port (``api``), with OSC
control addresses beside it for lighting desks (``osccontrol``). The page draws the streamed
vertices with WebGL and the desktop renderer's own shaders (``wire``). ``--program`` adds a window
with the face alone on a key colour, for window capture (``program``), and ``--ndi NAME`` an NDI
source with alpha (``ndi``).
"""
