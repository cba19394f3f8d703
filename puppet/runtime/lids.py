"""The eyelids' FAPs: which rigid part each turns, the feature point it moves by exactly its
value x IRISD, and which lower lid shares an eye with each upper one. One table, read by the FAP
engine (solving each lid's turn, limiting lids that would cross), the upper lids' closing shapes
and the eye corners' sliver guard."""

from __future__ import annotations

LID_FAPS = {19: ("upper_lid_l", "3.1", 1), 20: ("upper_lid_r", "3.2", 1),  # +: the point drops
            21: ("lower_lid_l", "3.3", -1), 22: ("lower_lid_r", "3.4", -1)}  # +: the point rises
"""Lid FAP: (its rigid part, its feature point, the sign of the point's drop per unit of the FAP)."""
LID_PARTS = frozenset(part for part, _, _ in LID_FAPS.values())
LID_PAIRS = ((19, 21), (20, 22))
"""(upper lid FAP, the lower lid FAP of the same eye)."""
