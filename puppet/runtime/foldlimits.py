"""How far this face's FAPs can go without folding the skin: the rig's ``fap_follow`` and
``fap_reach``, found on the face itself and applied at pose time (``FapEngine.shown``).

A fold is a triangle whose normal turns against its rest normal (``muscles.folded_triangles``).
``fap_coding_params.csv`` gives each FAP a coding range far beyond what a face can do (a brow
lowered by 900 ENS is 4 cm; a lip raised by 1860 MNS, 3.5 cm), so a FAP at its range end folds
the skin unless something limits it. Two limits can, both physical, both at pose time: the values
a file or a device gives are never changed, only what the face shows.

* **Follow** (``follow_ranges``): the inner and outer lip corners (2.4 / 8.3 and 2.5 / 8.4) are one
  corner of the mouth, 2 mm apart on the default face, each with its own FAPs (6 / 53, 7 / 54
  stretch them, 12 / 59, 13 / 60 raise them). One moved alone slides through the other within a
  millimetre (FAP 6 folded at 20 MW). Their difference is kept within the range that folds
  nothing: the FAP with the larger value leads and moves its own point by exactly value x FAPU;
  the other follows just enough. The visemes and expressions move both corners together and are
  not touched. Optional (``fold_safe(follow=True)``): the default rig ships without it, because
  the ARKit fits (``fit_faps``, linearised at neutral) cannot see one corner FAP pushing the
  other, and their median residual went from 0.40 to 0.50.
* **Reach** (``fold_free_reach``, with follow in place if any): each FAP alone is limited to the values it
  can take without a fold, toward each end of its range, the same on both sides of the face (the
  tighter of a FAP's and its mirror's) and 2% inside. It caps what no face does (a brow pulled
  4 cm into the eye, a jaw shifted 5 cm). Then ``widened``: where a fit of the artist's ARKit
  shapes uses more than the fold-free value (the lip corners, open_jaw to 815 MNS, the mid
  lips), the reach goes as far as the fit: a limit found one FAP at a time must not cut what an
  artist's expression needs (with every reach fold-free the ARKit fits' median residual went
  from 0.33 to 0.50). There a FAP alone at its range end can still fold thin triangles.

Before both, ``fold_safe`` fades the calibrated motions of the lid margin points toward the eye
corners as their lid's turn fades (``autorig``'s ``attach_weight`` there): the corners stay put,
and a margin vertex a fraction of a millimetre from one, moved by a brow or cheek FAP's motion,
folded the skin between them in the sad, fearful and surprised faces.

``fold_safe`` does the fading, follow and fold-free reach for a rigged face, after its
calibration (``puppet.runtime.fapcalibration`` is left as it is: its output goes through here);
``tools/build_default_rig.py`` then widens the reach to the ARKit fits and stores the result in
the default rig. The README's realism section lists what the limits cap on the default face.
"""

from __future__ import annotations

import copy

import numpy as np

from puppet.face.rig import Rig
from puppet.fap.table import fap
from puppet.runtime.fapcalibration import fold_free_reach
from puppet.runtime.fapengine import LID_FAPS
from puppet.runtime.runtime import Runtime

FOLLOW_SHARE = 0.5  # follow keeps a pair within half its fold-free difference: at a large common
# motion the corner folds sooner than at rest (at the whole difference, FAP 6 folded at 49 MW)
REACH_MARGIN = 0.98  # a little inside the fold-free value: float32 and float64 runtimes agree there
LID_PARTS = frozenset(part for part, _, _ in LID_FAPS.values())
CORNER_PAIRS = ((6, 53), (7, 54), (12, 59), (13, 60))  # (inner lip corner FAP, outer lip corner FAP)


def follow_ranges(runtime, pairs=CORNER_PAIRS, share: float = FOLLOW_SHARE) -> dict[tuple[int, int], tuple[float, float]]:
    """Per pair (a, b), the range (low, high) of value_a - value_b that folds nothing: the tighter
    of each FAP's own fold-free reach (a alone at d, or b alone at -d), found with no follow."""
    free = _with(runtime, fap_follow={}, fap_reach={})
    numbers = sorted({n for pair in pairs for n in pair})
    alone = fold_free_reach(free, numbers=numbers)
    unlimited = (-np.inf, np.inf)
    out = {}
    for a, b in pairs:
        (a_low, a_high), (b_low, b_high) = alone.get(a, unlimited), alone.get(b, unlimited)
        low, high = max(a_low, -b_high), min(a_high, -b_low)
        if np.isfinite(low) or np.isfinite(high):
            out[(a, b)] = (float(max(share * low, -1e9)), float(min(share * high, 1e9)))
    return out


def fold_limits(runtime) -> tuple[dict[tuple[int, int], tuple[float, float]], dict[int, tuple[float, float]]]:
    """(fap_follow, fap_reach) for the runtime's face and rig: follow first, then each FAP's
    fold-free reach with that follow in place."""
    follow = _symmetric(follow_ranges(runtime), _mirror_pair)
    return follow, _reach(_with(runtime, fap_follow=follow, fap_reach={}))


def _reach(runtime) -> dict[int, tuple[float, float]]:
    """Each FAP's fold-free reach on the runtime's rig, the same on both sides, a margin inside."""
    reach = _symmetric(fold_free_reach(runtime), mirror)
    return {n: (REACH_MARGIN * low, REACH_MARGIN * high) for n, (low, high) in reach.items()}


def widened(reach: dict[int, tuple[float, float]], needed) -> dict[int, tuple[float, float]]:
    """``reach`` widened to every value the FAP vectors ``needed`` (68 values each: the fits of
    the example shapes) use, on both sides of the face: a limit must not cut what an artist's
    expression needs, even where the FAP alone folds a thin triangle there."""
    values = np.stack(list(needed))
    low, high = values.min(axis=0), values.max(axis=0)
    out = {}
    for number, (r_low, r_high) in reach.items():
        both = [number] + ([mirror(number)] if mirror(number) else [])
        out[number] = (min(r_low, *(low[n - 1] for n in both)), max(r_high, *(high[n - 1] for n in both)))
    return out


def mirror(number: int) -> int | None:
    """The FAP of the other side (stretch_l_cornerlip <-> stretch_r_cornerlip), or None."""
    swap = {"l": "r", "r": "l", "lm": "rm", "rm": "lm"}
    words = fap(number).name.split("_")
    mirrored = "_".join(swap.get(w, w) for w in words)
    return fap(mirrored).number if mirrored != fap(number).name else None


def _mirror_pair(pair: tuple[int, int]) -> tuple[int, int] | None:
    mirrored = tuple(mirror(n) for n in pair)
    return None if None in mirrored else mirrored


def _symmetric(limits: dict, other_side) -> dict:
    """Limits that hold on both sides: each key's range and its mirror's, intersected, so that a
    symmetric expression stays symmetric (the mesh is not quite, and each side folds at its own
    value)."""
    out = dict(limits)
    for key, (low, high) in limits.items():
        other = other_side(key)
        if other is not None:
            o_low, o_high = limits.get(other, (-np.inf, np.inf))
            out[key] = out[other] = (max(low, o_low), min(high, o_high))
    return out


def fold_safe(runtime, *, follow: bool = False) -> Rig:
    """A copy of the runtime's (calibrated) rig with its lid margin motions faded toward the eye
    corners (``lid_faded``) and its ``fap_reach`` (and with ``follow``, its ``fap_follow``) found
    anew on that. The default rig ships without follow: it makes the lip corners' FAPs push each
    other, which the ARKit fits' linearisation (``fit_faps``) cannot see, and their median
    residual went from 0.40 to 0.50."""
    faded = _with(runtime, fap_motions=lid_faded(runtime.rig))
    rig = copy.copy(faded.rig)
    if follow:
        rig.fap_follow, rig.fap_reach = fold_limits(faded)
    else:
        rig.fap_follow = {}
        rig.fap_reach = _reach(_with(faded, fap_follow={}, fap_reach={}))
    return rig


def lid_faded(rig: Rig) -> dict[int, dict[str, np.ndarray]]:
    """The rig's FAP motions with each lid-carried point's motion scaled by its share of the lid's
    turn (``attach_weight``: 1 mid-lid, down to nearly 0 at the still eye corners)."""
    share = {p.name: p.attach_weight for p in rig.control_points if p.attach in LID_PARTS}
    return {number: {name: m * share.get(name, 1.0) for name, m in motions.items()}
            for number, motions in rig.fap_motions.items()}


def _with(runtime, **fields):
    """A runtime of the same face on a copy of its rig with ``fields`` replaced."""
    rig = copy.copy(runtime.rig)
    for name, value in fields.items():
        setattr(rig, name, value)
    return Runtime(runtime.face, rig, dtype=runtime.dtype)
