"""Carry a calibrated rig's FAP motions over to another face's rig.

``fap_motions`` (``puppet.face.rig``) are stored in FAPU, in the MPEG-4 face frame, on the points of a
skin grid that ``puppet.face.autorig`` lays out by the same rules on every face. Another face's grid
has other vertices, so motions travel by place, relative to the feature points: a thin-plate
spline through the feature points both faces share (``feature_warp``) takes each of the new face's
grid points to where it sits on the calibrated face, and the point takes the inverse-distance
blend of the motions of the ``NEIGHBOURS`` nearest calibrated points of the same region there. A
motion in FAPU becomes mesh units through the new face's own FAPU, so proportions carry over.
The calibration also moves feature points, along axes and for FAPs that do not define them (the
jaw's opening draws the lower lip's points back): those motions go to the same feature point of
the new face (3% of the motion, but without them the ARKit fits' median residual on the default
face itself rose from 0.30 to 0.35).

Two alternatives were measured with ``tools/checks/transfer_check.py`` and left out:

* in local frames: a motion travels in the frame of the skin under its point (the surface normal, and
  the face's x axis laid into the tangent plane), not in the face frame, so that a brow raise
  slides along a steeper forehead. On faces of other shapes with the artist's shapes as the truth
  it fitted worse (median residual 0.351 -> 0.390 and 0.358 -> 0.454 on two shape-model faces)
  and creased more (ICT: 20,926 -> 27,579 creased edges over the 21 poses).
* smoothed: two rounds of averaging each carried motion with those of its ``NEIGHBOURS`` nearest
  grid points of the region (half and half). Fewer creases on ICT (18,931) but worse fits
  (0.392, 0.360).

Neither caused ICT's forehead ridges: the motions sampled exactly from the default face's own
displacement field creased as much. The ridges were the jaw carrying the whole upper face
(``puppet.face.autorig``'s grid jaw share, fixed there).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.spatial import cKDTree

from puppet.face.rig import Rig

NEIGHBOURS = 4


def transfer_motions(source: Rig, source_face, target: Rig, target_face) -> dict[int, dict[str, np.ndarray]]:
    """``source``'s FAP motions (a rig of ``source_face``) for ``target``'s active points (a rig of
    ``target_face``); faces have vertices, triangles and feature points {FDP id: xyz}."""
    if not source.fap_motions:
        return {}
    warp = feature_warp(source_face.feature_points, target_face.feature_points)
    moved = sorted({name for motions in source.fap_motions.values() for name in motions})
    source_point = {p.name: p for p in source.control_points}  # Rig.point builds this dict every call
    target_point = {p.name: p for p in target.control_points}
    out: dict[int, dict[str, np.ndarray]] = {}
    for region in target.regions:
        names = [n for n in region.control_points if target_point[n].role == "active"
                 and not _feature_point(n)]
        members = set(_region_members(source, region.name))
        known = [n for n in moved if n in members]
        if not names or not known:
            continue
        tree = cKDTree(np.array([source_point[n].position for n in known]))
        where = warp(np.array([target_point[n].position for n in names]))
        distance, nearest = tree.query(where, k=min(NEIGHBOURS, len(known)))
        weights = 1.0 / np.maximum(np.atleast_2d(distance.T).T, 1e-9)
        weights /= weights.sum(axis=1, keepdims=True)
        nearest = np.atleast_2d(nearest.T).T
        for number, motions in source.fap_motions.items():
            table = np.array([motions.get(n, np.zeros(3)) for n in known])
            blended = np.einsum("pk,pka->pa", weights, table[nearest])
            keep = np.linalg.norm(blended, axis=1) > 0
            if keep.any():
                out.setdefault(number, {}).update(
                    {names[i]: blended[i] for i in np.flatnonzero(keep)})
    for number, motions in source.fap_motions.items():
        same = {n: np.array(m, float) for n, m in motions.items()
                if _feature_point(n) and n in target_point and target_point[n].role == "active"}
        if same:
            out.setdefault(number, {}).update(same)
    return out


def feature_warp(source_points: dict[str, np.ndarray], target_points: dict[str, np.ndarray]) -> RBFInterpolator:
    """The thin-plate spline that takes points of the target face to where they sit on the source
    face, through the feature points {FDP id: xyz} both faces have; of target points at one place,
    the first in FDP order only (the spline's system is singular with both: its solution was
    1e14 off, and differed between scipy releases)."""
    shared = sorted(set(source_points) & set(target_points))
    nodes = np.array([target_points[k] for k in shared], dtype=float)
    values = np.array([source_points[k] for k in shared], dtype=float)
    first = np.sort(np.unique(nodes, axis=0, return_index=True)[1])
    return RBFInterpolator(nodes[first], values[first], kernel="thin_plate_spline")


def _region_members(rig: Rig, region: str) -> list[str]:
    return next((r.control_points for r in rig.regions if r.name == region), [])


def _feature_point(name: str) -> bool:
    """FDP ids ("8.3") name the feature points: FAPs move those by definition."""
    group, _, index = name.partition(".")
    return group.isdigit() and index.isdigit()
