"""Where the shared benchmark assets are: ``../shared/assets`` beside the repository (the ICT and
MediaPipe faces, the MakeHuman ARKit shapes), read from there and never copied into the project."""

from __future__ import annotations

import os
from pathlib import Path


def shared_assets() -> Path:
    """``../shared/assets`` beside the repository (``$FACEPUPPET_SHARED`` overrides ../shared)."""
    root = os.environ.get("FACEPUPPET_SHARED")
    if root:
        return Path(root) / "assets"
    return Path(__file__).resolve().parents[3] / "shared" / "assets"
