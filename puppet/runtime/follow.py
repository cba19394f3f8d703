"""A follow pair's range: how far two FAPs moving a lip edge may differ, narrowing as they move together.

A pair (a, b) moves an inner and an outer lip point a hair's breadth apart (``rig.fap_follow``).
At rest their difference a - b may take (low, high) without a fold. Moved together by
m = (a + b) / 2 the edge folds sooner, and at the pair's common reach (``m_low`` < 0 < ``m_high``:
both moved together fold there) no difference is safe. The range narrows linearly in between:

    low s(m) <= a - b <= high s(m),    s(m) = 1 - max(m / m_high, m / m_low)

which is four half-planes p a + q b <= r (``rows``), so a fit keeps within them as linear
constraints, and at pose time the FAP with the larger value leads and the other moves just enough
to come inside (``follower``). A pair whose common reach is infinite keeps its rest range (the rig
files before the common reach was measured). On the default face the lip corner's pair (12 / 59)
may differ by 145 MNS at rest but only 40 at 700 MNS, where the corner alone used to fold: narrowed,
the corner alone goes as far as the pair does together.
"""

from __future__ import annotations

import numpy as np


def rows(low: float, high: float, m_low: float = -np.inf, m_high: float = np.inf) -> np.ndarray:
    """(4, 3): the range as half-planes (p, q, r), p a + q b <= r: high and low at the m_high side,
    then at the m_low side."""
    out = []
    for common in (m_high, m_low):
        k = 1 / (2 * common) if np.isfinite(common) else 0.0
        out.append((1 + high * k, -1 + high * k, high))  # a - b <= high (1 - (a + b) k)
        out.append((-(1 + low * k), 1 - low * k, -low))  # a - b >= low (1 - (a + b) k)
    return np.array(out)


def follower(rows_: np.ndarray, a: float, b: float) -> tuple[float, float]:
    """(a, b) brought inside the range: the one with the larger magnitude leads and keeps its value,
    the other moves as little as comes inside (to the leader's value when nothing does: past the
    common reach)."""
    lead_a = abs(a) >= abs(b)
    lead, own = (a, b) if lead_a else (b, a)
    p, q = (rows_[:, 0], rows_[:, 1]) if lead_a else (rows_[:, 1], rows_[:, 0])
    limit = (rows_[:, 2] - p * lead) / q  # q is never 0: |q| = |1 +- range / (2 common)| with range < common
    low = np.max(limit[q < 0], initial=-np.inf)
    high = np.min(limit[q > 0], initial=np.inf)
    moved = lead if low > high else float(np.clip(own, low, high))
    return (lead, moved) if lead_a else (moved, lead)
