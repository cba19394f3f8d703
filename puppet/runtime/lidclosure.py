"""A closing eye's margins meet along their whole length, not only in the middle.

A lid FAP turns its margin about the eyeball so that the middle point (3.1 / 3.2) drops by
exactly value x IRISD: at 1024 IRISD it lies on the lower lid's middle point. The rest of the
margin takes a share of the turn that fades toward the still eye corners (``lid_shares``), and
the calibrated FAP motions add the artists' own motions of those points, so on the default face
a blink with the upper lids alone left 8.4% of the eyes' opening, the outer half 1.6 mm open and
the white of the eye showing (``tools/checks/eye_closure.py``). The artists' blinks close it all (0.1%
left).

So each upper lid has a closing shape, as a rigger sculpts one: where the two lids meet (the
upper lid's drop plus the lower lid's rise = ``LIDS_MEET``), the motion that brings each point
of its margin onto the lower margin (at the same place across the eye, on the lower margin's
curve), times the point's share of the lid's turn. Toward the still corners the points go less
than all the way: brought all the way down, the 1 mm triangles beside the outer corner fold, and
the sliver guard, which keeps them, pushed the whole outer margin open again (8.9% left). With
the shares, 3.4% is left at 1024 IRISD (the corners' last 1 mm), 0.5% with the lower lid taking
its share of the closing as the artists' blinks do (800 + 224; 2.7% before), and nothing folds.

The shape is sampled with the lower lid taking none, a quarter and half of the closing
(``SPLITS``), in the frame before the lids carry their points (the lid's turn is undone, so that
carried it gives the sampled motion), and it fades in from ``ONSET`` of the closing with a
smoothstep: below that a lid moves exactly as its FAPs say. A FAP's own feature point is never
moved (its FAP moves it by exactly value x FAPU), nor is the lower lid.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from puppet.fap.highlevel import fap_values
from puppet.runtime.lids import LID_FAPS, LID_PAIRS

ONSET = 0.6
"""The share of the closing (upper drop + lower rise over ``LIDS_MEET``) where the shape starts."""
SPLITS = (0.0, 0.25, 0.5)
"""The lower lid's shares of the closing at which the shape is sampled (beyond them, the last)."""

Controls = Callable[[np.ndarray], tuple[np.ndarray, dict[str, np.ndarray]]]


class LidClosure:
    """``add(values, d)``: the closing shapes for 68 shown FAP values, added to the control point
    displacements ``d`` (K, 3) in place."""

    def __init__(self, runtime, controls: Controls, meet: float) -> None:
        self.meet = meet
        self.sides = [side for side in (_ClosingShape.sampled(runtime, controls, meet, upper, lower)
                                        for upper, lower in LID_PAIRS) if side is not None]

    def add(self, values: np.ndarray, d: np.ndarray) -> None:
        """Add each closing lid's shape, faded in by how far it closes, to ``d`` in place."""
        for side in self.sides:
            upper, lower = float(values[side.number - 1]), max(float(values[side.lower_number - 1]), 0.0)
            closing = (upper + lower) / self.meet
            if closing > ONSET:
                fade = min((closing - ONSET) / (1.0 - ONSET), 1.0)
                split = lower / (upper + lower)
                d[side.rows] += (fade * fade * (3.0 - 2.0 * fade) * side.at(split)).astype(d.dtype)


class _ClosingShape:
    """One upper lid's closing shape: the rows (into ``control_points``) it moves and, per split
    in ``SPLITS``, their motions before the lids carry them."""

    def __init__(self, number: int, lower_number: int, rows: np.ndarray, motions: np.ndarray) -> None:
        self.number, self.lower_number = number, lower_number
        self.rows, self.motions = rows, motions

    def at(self, split: float) -> np.ndarray:
        """The shape's motions (len(rows), 3) at the lower lid's share ``split`` of the closing."""
        k = np.interp(split, SPLITS, np.arange(len(SPLITS)))
        low = int(k)
        high = min(low + 1, len(SPLITS) - 1)
        return (1.0 - (k - low)) * self.motions[low] + (k - low) * self.motions[high]

    @classmethod
    def sampled(cls, runtime, controls: Controls, meet: float, number: int,
                lower_number: int) -> _ClosingShape | None:
        """The shape of upper lid FAP ``number``'s lid closing onto lower lid FAP
        ``lower_number``'s, None where the rig has not both lids or no margin points on them (a rig
        made elsewhere may carry none)."""
        upper_part, lower_part = LID_FAPS[number][0], LID_FAPS[lower_number][0]
        if upper_part not in runtime.rig.rigid_parts or lower_part not in runtime.rig.rigid_parts:
            return None
        feature = set(runtime.face.feature_points)
        points = runtime.rig.control_points
        index = {name: i for i, name in enumerate(runtime.control_points)}
        upper = np.array([index[p.name] for p in points if p.attach == upper_part and p.name not in feature],
                         dtype=np.int64)
        lower = np.array([index[p.name] for p in points if p.attach == lower_part], dtype=np.int64)
        if not len(upper) or not len(lower):
            return None
        shares = runtime.muscle_shares
        motions = []
        for split in SPLITS:
            d, rigid = controls(fap_values({number: (1.0 - split) * meet, lower_number: split * meet}))
            positions = runtime.control_positions(d, rigid)
            moves = shares[upper, None] * (_onto(positions[upper], positions[lower]) - positions[upper])
            motions.append(_uncarried(moves, rigid.get(upper_part), shares[upper]))
        return cls(number, lower_number, upper, np.array(motions))


def _onto(points: np.ndarray, margin: np.ndarray) -> np.ndarray:
    """Each of ``points`` moved onto the ``margin`` polyline at its own x (across the eye)."""
    margin = margin[np.argsort(margin[:, 0])]
    x = points[:, 0]
    return np.stack([x, np.interp(x, margin[:, 0], margin[:, 1]), np.interp(x, margin[:, 0], margin[:, 2])], axis=1)


def _uncarried(moves: np.ndarray, motion: np.ndarray | None, shares: np.ndarray) -> np.ndarray:
    """The displacements that, carried by a lid turned by ``motion`` with each point's share of
    its turn (``w R e + (1 - w) e``), move the points by ``moves``."""
    if motion is None:
        return moves
    w = np.asarray(shares, dtype=float)[:, None, None]
    carry = w * motion[:, :3] + (1.0 - w) * np.eye(3)
    return np.linalg.solve(carry, moves[:, :, None])[:, :, 0]
