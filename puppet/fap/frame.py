"""One frame of a FAP stream, as a stream sends it: the masked FAPs and the FAP 1 / 2 fields."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FapFrame:
    """One frame: ``number`` as written, ``values``/``mask`` (68,), FAP 1/2 fields (4,) / (6,): the
    viseme (select1, select2, blend, def) and expression (select1, intensity1, select2,
    intensity2, init_face, def) as ``puppet.io.fapfile`` reads them."""

    number: int
    values: np.ndarray
    mask: np.ndarray
    viseme: np.ndarray
    expression: np.ndarray
