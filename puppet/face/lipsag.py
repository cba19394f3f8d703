"""How far a pose pulls the lower lip's middle below its sides: a V where the lip should stay round.

The lower lip's outer edge runs through MPEG-4's 8.8, 8.2 and 8.7 (right side, middle, left side).
A rig whose DFFD interpolates that edge between them drops the edge as a tent when the middle
point moves alone: fitted to an open mouth whose lip sides drop too far with the jaw, the middle
is pulled down past them and the lip comes to a point. ``lower_lip_sag`` measures it on a
displacement field, so the face's pose and the artist's same shape can be put side by side.
"""

from __future__ import annotations

import numpy as np

MIDDLE, SIDES = "8.2", ("8.7", "8.8")
"""The lower lip's outer edge: its middle and its two sides (MPEG-4 feature points)."""


def lower_lip_sag(face, displacement: np.ndarray) -> float:
    """How much further (in the face's units, along y) ``displacement`` (N, 3) moves the middle of
    the lower lip's outer edge down than the mean of its sides: above 0 the middle hangs below
    them (a V), below 0 it rises above them."""
    vertices = face.feature_vertices
    sides = np.mean([displacement[vertices[side], 1] for side in SIDES])
    return float(sides - displacement[vertices[MIDDLE], 1])
