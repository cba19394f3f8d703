"""Carry a calibrated rig's FAP motions over to another face's rig.

``fap_motions`` (``puppet.face.rig``) are stored in FAPU, in the MPEG-4 face frame, on the points of a
skin grid that ``puppet.face.autorig`` lays out by the same rules on every face. Another face's grid
has other vertices, so motions travel by place, relative to the feature points: a thin-plate
spline through the feature points both faces share takes each of the new face's grid points to
where it sits on the calibrated face, and the point takes the inverse-distance blend of the
motions of the ``NEIGHBOURS`` nearest calibrated points of the same region there. A motion in
FAPU becomes mesh units through the new face's own FAPU, so proportions carry over.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.spatial import cKDTree

from puppet.face.rig import Rig

NEIGHBOURS = 4


def transfer_motions(source: Rig, source_points: dict[str, np.ndarray], target: Rig,
                     target_points: dict[str, np.ndarray]) -> dict[int, dict[str, np.ndarray]]:
    """``source``'s FAP motions for ``target``'s active points; ``*_points`` are each face's
    feature points {FDP id: xyz}."""
    if not source.fap_motions:
        return {}
    warp = feature_warp(source_points, target_points)
    moved = sorted({name for motions in source.fap_motions.values() for name in motions})
    out: dict[int, dict[str, np.ndarray]] = {}
    source_point = {p.name: p for p in source.control_points}  # Rig.point builds this dict every call
    target_point = {p.name: p for p in target.control_points}
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
    return out


def feature_warp(source_points: dict[str, np.ndarray], target_points: dict[str, np.ndarray]) -> RBFInterpolator:
    """The thin-plate spline that takes points of the target face to where they sit on the source
    face, through the feature points {FDP id: xyz} both faces have."""
    shared = sorted(set(source_points) & set(target_points))
    return RBFInterpolator(np.array([target_points[k] for k in shared]),
                           np.array([source_points[k] for k in shared]), kernel="thin_plate_spline")


def _region_members(rig: Rig, region: str) -> list[str]:
    return next((r.control_points for r in rig.regions if r.name == region), [])


def _feature_point(name: str) -> bool:
    """FDP ids ("8.3") name the feature points: FAPs move those by definition."""
    group, _, index = name.partition(".")
    return group.isdigit() and index.isdigit()
