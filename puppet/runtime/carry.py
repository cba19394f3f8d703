"""The input points that ride on rigid parts (the lower lip and chin on the jaw, the lid margins
on the lids): each moves with its part's motion by its attach weight, on top of its own
displacement.

Every frame carries a few hundred such points on up to five parts (the live slider box moves
all five). Carried part by part, that was five rounds of small numpy calls, whose overhead, not
their arithmetic, was the cost; here the points of the parts that move are one batch, each row
picking its part's motion, so a frame costs the same handful of calls however many parts move.
"""

from __future__ import annotations

import numpy as np


class Carry:
    """The inputs attached to each rigid part: ``parts`` maps a part to (its attached inputs'
    rows, their rest positions (n, 3), their attach weights (n, 1))."""

    def __init__(self, parts: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]) -> None:
        self.parts = parts
        self._batches: dict[tuple[str, ...], tuple[np.ndarray, ...]] = {}

    def key(self, rigid: dict[str, np.ndarray]) -> bytes:
        """The motions of the carrying parts in ``rigid``, as bytes: what a carried field depends on."""
        return b"".join(part.encode() + rigid[part].tobytes() for part in self.parts if part in rigid)

    def carry(self, out: np.ndarray, rigid: dict[str, np.ndarray]) -> None:
        """Move the attached rows of inputs ``out`` (displacements from their rest positions, in
        place) with their parts' motions in ``rigid``, by their weights: the inputs' displacements
        with the parts where they are."""
        batch = self._batch(rigid)
        if batch is not None:
            rows, p0, w, motions = batch
            own = out[rows]
            moved = np.einsum("rij,rj->ri", motions[:, :, :3], p0 + own) + motions[:, :, 3] - p0
            out[rows] = w * moved + (1 - w) * own

    def turn(self, out: np.ndarray, rigid: dict[str, np.ndarray]) -> None:
        """``carry`` for an addition to the displacements (its carry is affine in them, so an
        addition is turned by the rotations alone)."""
        batch = self._batch(rigid)
        if batch is not None:
            rows, _, w, motions = batch
            own = out[rows]
            out[rows] = w * np.einsum("rij,rj->ri", motions[:, :, :3], own) + (1 - w) * own

    def _batch(self, rigid: dict[str, np.ndarray]) -> tuple[np.ndarray, ...] | None:
        """(rows, rest positions, weights, each row's part motion (n, 3, 4)) of the parts in
        ``rigid``, or None where none of them moves; the rows are gathered once per set of parts."""
        moving = tuple(part for part in self.parts if part in rigid)
        if not moving:
            return None
        if moving not in self._batches:
            rows, p0, w = (np.concatenate(a) for a in zip(*(self.parts[part] for part in moving)))
            which = np.repeat(np.arange(len(moving)), [len(self.parts[part][0]) for part in moving])
            self._batches[moving] = rows, p0, w, which
        rows, p0, w, which = self._batches[moving]
        return rows, p0, w, np.stack([rigid[part] for part in moving])[which]
