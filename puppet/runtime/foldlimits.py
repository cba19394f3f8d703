"""How far this face's FAPs can go without folding the skin: the rig's ``fap_follow`` and
``fap_reach``, found on the face itself and applied at pose time (``FapEngine.shown``).

A fold is a triangle whose normal turns against its rest normal (``puppet.runtime.musclesolver.folded_triangles``).
``fap_coding_params.csv`` gives each FAP a coding range far beyond what a face can do (a brow
lowered by 900 ENS is 4 cm; a lip raised by 1860 MNS, 3.5 cm), so a FAP at its range end folds
the skin unless something limits it. Two limits can, both physical, both at pose time: the values
a file or a device gives are never changed, only what the face shows.

* **Follow** (``follow_ranges``): each inner lip point (2.2-2.9) and the outer lip point beside it
  (8.1-8.8) are one edge of the lip, 1-3 mm apart, each moved by its own FAP (``LIP_PAIRS``:
  lower_t_midlip 4 and lower_t_midlip_o 51, ..., raise_r_cornerlip 13 and raise_r_cornerlip_o 60).
  One moved alone slides through the other within a few millimetres (stretch_l_cornerlip 6 alone
  folded at 20 MW, raise_b_midlip 5 alone at -480 MNS). Their difference is kept within three
  quarters of the range that folds nothing (``FOLLOW_SHARE``; half for the lip stretch, ``STRETCH``):
  the FAP with the larger value leads and moves its own point by exactly value x FAPU; the other
  follows just enough. The visemes and expressions mostly move both together and are not
  touched. Where the pair moved together goes further than the nearer of
  the two alone, the range narrows toward that common reach (``puppet.runtime.follow``): the lip
  corner raised alone folded the skin beside it from 490 MNS with its outer twin 145 MNS behind,
  while the two together go to 705, so the outer corner now comes along and the corner reaches
  691 (a smile's fit puts it at 600, the end of its coding range; it was capped at 480).
* **Reach** (``fold_free_reach``, with follow in place): each FAP alone is limited to the values
  it can take without a fold, toward each end of its range, the same on both sides of the face
  (the tighter of a FAP's and its mirror's) and 2% inside. It caps what no face does (a brow
  pulled 4 cm into the eye, a jaw shifted 5 cm). Except toward the high end of the ``NEEDED``
  FAPs (open_jaw, the upper lids closing), which go as far as the artist's shapes take them
  (``needed_reach``): the slivers a closing lid folds at the eye corners are kept from folding
  by the runtime's sliver guard (``puppet.runtime.sliverguard``); open_jaw goes as far as the
  examples' fits go within the other limits (``within_limits``), short of the chin's fold (four
  quads beside the lip corners folded until they were split along the other diagonal,
  ``tools/builders/build_default_face.py``'s ``TURNED_QUADS``).

Fits see both limits (``puppet.runtime.fapcalibration``: each fit keeps within the reach, and within
the follow ranges as linear constraints, so the values it finds are what the face shows).
``fold_safe_calibration`` is the calibration the default rig ships: calibrate, find the limits,
and fit every example within them. (Calibrating once more with the fits inside the limits, so
that the motions learn from values the face shows, moved the ARKit fits' median residual only
from 0.326 to 0.323 and folded joy and fear: not done.)

Before the limits, ``fold_safe`` fades the calibrated motions of the lid margin points toward
the eye corners as their lid's turn fades (``autorig``'s ``attach_weight`` there): the corners
stay put, and a margin vertex a fraction of a millimetre from one, moved by a brow or cheek
FAP's motion, folded the skin between them in the sad, fearful and surprised faces (and the
upper lids' own closing motions, unfaded, fold 9 triangles a side from 900 IRISD that the sliver
guard cannot hold; faded less, by the square root of the share or at the corners only, still
8-9). The gaze FAPs' and the lower lids' motions are not faded (``UNFADED``): they fold nothing
at any range end, in any expression or viseme, and faded they cost the eye-look shapes their
lids' follow near the corners (eyeLookIn/Out 0.34 -> 0.40 relative residual, eyeLookUp/Down
0.30 -> 0.31-0.32; the lower lids' alone, eyeLookUp 0.296 -> 0.304).

The guide's contributors/realism.md lists what the limits cap on the default face.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable

import numpy as np

from puppet.face.default import default_face, load_default_rig
from puppet.face.rig import Rig
from puppet.fap.table import fap
from puppet.runtime.creasesmoothing import crease_smoothed
from puppet.runtime.fapcalibration import Calibration, calibrate, common_reach, fit_faps, fold_free_reach
from puppet.runtime.fapengine import GAZE_FAPS, lid_shares
from puppet.runtime.foldsearch import Bisection, FoldSearch
from puppet.runtime.posecheck import folded_vertices
from puppet.runtime.runtime import Runtime

FOLLOW_SHARE = 0.75  # follow keeps a pair within three quarters of its fold-free difference: at a
# large common motion the lip folds sooner than at rest (at the whole difference, FAP 6 folded at
# 49 MW); at half, jawRight and mouthRight lost their lower lip's roll (held-out relative residual
# 0.291 and 0.290 at three quarters, 0.304 and 0.301 at half)
STRETCH = (6, 7)
STRETCH_SHARE = 2 / 3  # of FOLLOW_SHARE for the stretch pairs (6 / 53, 7 / 54): at three quarters
# viseme 12 (jaw 140 MNS, lips stretched 190 MW, corners raised 70) folded the upper lip's middle
REACH_MARGIN = 0.98  # a little inside the fold-free value: float32 and float64 runtimes agree there
UNFADED = (*GAZE_FAPS, 21, 22)
"""FAPs whose motions ``lid_faded`` leaves as calibrated: the gaze (the lids follow the eyeball)
and close_b_l/r_eyelid (the lower lids: unfaded they fold nothing, and faded they cost eyeLookUp
its lower lid, 0.304 -> 0.296 relative residual held out); the upper lids' closing stays faded."""
NEEDED = (3, 19, 20)
"""FAPs whose reach goes toward their high end as far as the artist's shapes take them (the
fits of the examples within the other limits, ``within_limits``): open_jaw up to where it folds
(jawOpen would open it to 916 MNS; two triangles on the chin turn over from 913, so it stops
there, not at the fold-free reach 2% inside) and close_t_l/r_eyelid whether or not they fold (past
about 645 IRISD the tiny triangles at the eye corners would turn over, but the sliver guard
keeps them: ``GUARDED``; a blink closes at 1024). Capped fold-free, the face could not blink."""
GUARDED = (19, 20)
"""``NEEDED`` FAPs whose folds the sliver guard holds: their reach is not capped at the fold."""
LIP_PAIRS = tuple((n, n + 47) for n in range(4, 14))
"""(inner lip FAP, outer lip FAP): the FAPs 4-13 move the inner lip points 2.x, 51-60 the outer
ones 8.x beside them, along the same axes and in the same units."""


def follow_ranges(search: Bisection, pairs=LIP_PAIRS,
                  share: float = FOLLOW_SHARE) -> dict[tuple[int, int], tuple[float, ...]]:
    """Per pair (a, b), the range (low, high) of value_a - value_b that folds nothing at rest: the
    tighter of each FAP's own fold-free reach (a alone at d, or b alone at -d), and the pair's
    common reach (m_low, m_high): where both moved together fold (``puppet.runtime.follow``: the
    range narrows to nothing there). Found with no follow, by ``search`` (``puppet.runtime.foldsearch``,
    on a runtime without fold limits)."""
    free = search.with_follow({})
    numbers = sorted({n for pair in pairs for n in pair})

    def asks(reach) -> None:
        fold_free_reach(free.runtime, numbers=numbers, reach=reach)
        for pair in pairs:
            common_reach(free.runtime, list(pair), reach=reach)

    free.ahead(asks)
    alone = fold_free_reach(free.runtime, numbers=numbers, reach=free)
    unlimited = (-np.inf, np.inf)
    out = {}
    for a, b in pairs:
        (a_low, a_high), (b_low, b_high) = alone.get(a, unlimited), alone.get(b, unlimited)
        low, high = max(a_low, -b_high), min(a_high, -b_low)
        if np.isfinite(low) or np.isfinite(high):
            kept = share * STRETCH_SHARE if a in STRETCH else share
            common = common_reach(free.runtime, [a, b], reach=free)
            out[(a, b)] = (float(max(kept * low, -1e9)), float(min(kept * high, 1e9)), *common)
    return out


def fold_limits(runtime, search: type[Bisection] = FoldSearch
                ) -> tuple[dict[tuple[int, int], tuple[float, ...]], dict[int, tuple[float, float]]]:
    """(fap_follow, fap_reach) for the runtime's face and rig: follow first, then each FAP's
    fold-free reach with that follow in place. A pair's range narrows toward its common reach
    only on a side where the pair together goes further than the nearer of its two FAPs does
    alone within the rest range (``_narrowed``: the lip corner); elsewhere it stays as at rest.
    The rig's own limits do not apply (a runtime whose rig has a reach is set up again without
    it, and without its ``guarded``: a reach is where the face folds, not where the guard stops
    holding it). ``search`` finds each reach (``puppet.runtime.foldsearch``: ``Bisection`` is the
    plain search, the reference; ``FoldSearch`` gives its values with a few trials each)."""
    limited = runtime.rig.fap_reach or len(runtime.rig.guarded)
    free = search(_with(runtime, fap_follow={}, fap_reach={}, guarded=np.zeros(0, dtype=np.int64)) if limited else runtime)
    ranges = _symmetric(follow_ranges(free), _mirror_pair)
    at_rest = {pair: (low, high, -np.inf, np.inf) for pair, (low, high, _, _) in ranges.items()}
    alone = _reach(free.with_follow(at_rest))
    follow = {pair: _narrowed(pair, r, alone) for pair, r in ranges.items()}
    return follow, _reach(free.with_follow(follow))


def _narrowed(pair: tuple[int, int], ranges: tuple[float, ...], reach: dict[int, tuple[float, float]]) -> tuple[float, ...]:
    """A pair's (low, high, m_low, m_high) keeping a common reach only on a side where it passes
    the nearer of the two FAPs' ``reach`` (the other side's is made infinite: no narrowing)."""
    low, high, m_low, m_high = ranges
    a, b = (reach.get(n, (-np.inf, np.inf)) for n in pair)
    return (low, high, m_low if m_low < max(a[0], b[0]) else -np.inf, m_high if m_high > min(a[1], b[1]) else np.inf)


def _reach(search: Bisection) -> dict[int, tuple[float, float]]:
    """Each FAP's fold-free reach on the search's runtime, the same on both sides, a margin inside."""
    search.ahead(lambda reach: fold_free_reach(search.runtime, reach=reach))
    reach = _symmetric(fold_free_reach(search.runtime, reach=search), mirror)
    return {n: (REACH_MARGIN * low, REACH_MARGIN * high) for n, (low, high) in reach.items()}


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
    """Limits that hold on both sides: each key's and its mirror's intersected (the larger of their
    lower ends, the smaller of their upper ends: (low, high) or follow's (low, high, m_low, m_high)),
    so that a symmetric expression stays symmetric (the mesh is not quite, and each side folds at
    its own value)."""
    out = dict(limits)
    for key, ends in limits.items():
        other = other_side(key)
        if other is not None:
            mirrored = limits.get(other, (-np.inf, np.inf) * (len(ends) // 2))
            out[key] = out[other] = tuple((max if k % 2 == 0 else min)(end, o) for k, (end, o) in enumerate(zip(ends, mirrored)))
    return out


def fold_safe(runtime) -> Rig:
    """A copy of the runtime's (calibrated) rig with its lid margin motions faded toward the eye
    corners (``lid_faded``) and its ``fap_follow`` and ``fap_reach`` found anew on that (with no
    ``guarded``: ``within_limits`` finds it last)."""
    faded = _with(runtime, fap_motions=lid_faded(runtime.rig), fap_follow={}, fap_reach={},
                  guarded=np.zeros(0, dtype=np.int64))
    rig = copy.copy(faded.rig)
    rig.fap_follow, rig.fap_reach = fold_limits(faded)
    return rig


FOLD_STEPS = ("smoothing the skin where the expressions and visemes crease",
              "fold limits: how far each FAP goes before a triangle folds (the longest step)",
              "the triangles the expressions and visemes still fold, to guard")
"""The three parts of ``fold_limited``, in order, as ``step`` hears them (``puppet rig``'s progress)."""


def fold_limited(face, rig: Rig, search: type[Bisection] = FoldSearch,
                 step: Callable[[str], None] | None = None) -> Rig:
    """A copy of a new face's ``rig`` with its ``fap_follow`` and ``fap_reach`` found on ``face``
    (``fold_limits``): what ``puppet rig`` and ``puppet face-from-photo`` give a face, whose
    motions are the default face's carried over (their lid margins faded already). The upper lids'
    closing stays open (``GUARDED``: a blink must close, the sliver guard holds its folds); with no
    example shapes to say how far the face needs open_jaw, it stops where it folds. On the ICT
    face the six expressions folded 2,368 triangles without these limits and 102 with them; the
    triangles the expressions and visemes still fold within them (FAPs that fold nothing alone
    fold together) are the rig's ``guarded``, which the runtime's fold guard keeps from folding.
    Before the limits are searched, the skin is smoothed where the poses crease
    (``puppet.runtime.creasesmoothing``; the rig's ``smoothed``), so the limits hold for the face as
    it moves. ``search``: as for ``fold_limits``; ``step(what)`` hears each of ``FOLD_STEPS`` as it
    starts (on ICT here: 6, 15 and 2 seconds)."""
    step = step or (lambda what: None)
    out = copy.copy(rig)
    none = np.zeros(0, dtype=np.int64)
    out.fap_follow, out.fap_reach, out.guarded, out.smoothed = {}, {}, none, none
    reference = Runtime(default_face(), load_default_rig(), guard=False)
    step(FOLD_STEPS[0])
    runtime = crease_smoothed(Runtime(face, out, guard=False), reference)
    out.smoothed = runtime.rig.smoothed
    step(FOLD_STEPS[1])
    out.fap_follow, reach = fold_limits(runtime, search)
    out.fap_reach = {n: (low, np.inf) if n in GUARDED else (low, high) for n, (low, high) in reach.items()}
    step(FOLD_STEPS[2])
    out.guarded = folded_vertices(runtime.with_limits(out.fap_follow, out.fap_reach))
    return out


def fold_safe_calibration(face, examples, *, rig: Rig | None = None, held_out: tuple[str, ...] = ()) -> Calibration:
    """``calibrate`` (``puppet.runtime.fapcalibration``) made fold-safe (``within_limits``). A rig
    that is calibrated already is the calibration's prior with its lid margin motions unfaded
    first (``lid_unfaded``): calibrated again, a rig's lids are faded once, not once more."""
    if rig is not None and rig.fap_motions:
        rig = copy.copy(rig)
        rig.fap_motions = lid_unfaded(rig)
    return within_limits(face, calibrate(face, examples, rig=rig, held_out=held_out), examples)


def within_limits(face, calibration: Calibration, examples) -> Calibration:
    """The calibration's rig made ``fold_safe``, the reach of the ``NEEDED`` FAPs opened to what
    the examples use within the other limits, and every example fitted on it within its limits
    (``weights``: what the face shows for it).

    What an example uses is measured twice: fitted with the ``NEEDED`` FAPs unlimited, then
    within the reach that gives. The second fits use less where the other limits bind (the
    jawOpen fit opens the jaw 930 MNS unlimited, 916 within the lids' and lips' limits), and
    the reach keeps only that, short of where the FAP alone folds unless the sliver guard holds
    it (open_jaw folds the chin from 913 MNS and stops there). What the expressions and visemes
    still fold within the limits is the rig's ``guarded`` (on the default face: joy's corner slivers)."""
    safe = fold_safe(Runtime(face, calibration.rig))
    fold_free = dict(safe.fap_reach)
    safe.fap_reach = {n: r for n, r in fold_free.items() if n not in NEEDED}
    for _ in range(2):  # the NEEDED FAPs unlimited, then within the reach that gave
        safe.fap_reach = needed_reach(face, safe, examples, fold_free)
    weights = _fits(Runtime(face, safe, dtype=np.float64), examples)
    safe.guarded = folded_vertices(Runtime(face, safe))
    return dataclasses.replace(calibration, rig=safe, weights=weights)


def needed_reach(face, rig: Rig, examples, fold_free: dict[int, tuple[float, float]]) -> dict[int, tuple[float, float]]:
    """``fold_free`` with each ``NEEDED`` FAP's high end raised to the largest value a fit of the
    examples on ``rig`` gives it (or its mirror), short of where it folds unless ``GUARDED``."""
    used = np.max(list(_fits(Runtime(face, rig, dtype=np.float64), examples).values()), axis=0)
    reach = dict(fold_free)
    for number in NEEDED:
        low, high = reach.get(number, (-np.inf, np.inf))
        both = [number] + ([mirror(number)] if mirror(number) else [])
        wanted = max(high, *(float(used[n - 1]) for n in both))
        reach[number] = (low, wanted if number in GUARDED else min(wanted, high / REACH_MARGIN))
    return reach


def _fits(runtime: Runtime, examples) -> dict[str, np.ndarray]:
    """Each non-zero example's ``fit_faps`` on ``runtime``."""
    return {name: fit_faps(runtime, D) for name, D in examples.items() if np.any(D)}


def lid_faded(rig: Rig) -> dict[int, dict[str, np.ndarray]]:
    """The rig's FAP motions with each lid-carried point's motion scaled by its share of the lid's
    turn (``attach_weight``: 1 mid-lid, down to nearly 0 at the still eye corners), except the
    ``UNFADED`` FAPs': the lids follow the eyeball to the corners, and the lower lids' own motions
    fold nothing at any range end."""
    return _by_lid_share(rig, lambda motion, share: motion * share)


def lid_unfaded(rig: Rig) -> dict[int, dict[str, np.ndarray]]:
    """``lid_faded`` undone: each lid-carried point's motion divided by its share of the lid's turn
    (a share of 0 leaves the motion as it is), except the ``UNFADED`` FAPs'."""
    return _by_lid_share(rig, lambda motion, share: motion / share if share > 0 else motion)


def _by_lid_share(rig: Rig, scaled) -> dict[int, dict[str, np.ndarray]]:
    """The rig's FAP motions, each point's as ``scaled(motion, share)`` with its share of its lid's
    turn (1 off the lids), except the ``UNFADED`` FAPs', kept as they are."""
    share = lid_shares(rig)
    return {number: motions if number in UNFADED
            else {name: scaled(m, share.get(name, 1.0)) for name, m in motions.items()}
            for number, motions in rig.fap_motions.items()}


def _with(runtime, **fields):
    """A runtime of the same face on a copy of its rig with ``fields`` replaced."""
    rig = copy.copy(runtime.rig)
    for name, value in fields.items():
        setattr(rig, name, value)
    return Runtime(runtime.face, rig, dtype=runtime.dtype)
