"""Which vertices of a face rigged by transfer are smoothed: those around the edges its expressions
and visemes crease.

On a mesh finer than the default face's (``FINER``), the six expressions and 15 visemes
(``puppet.runtime.posecheck.POSES``) are checked against the default face in the same poses
(``PoseCheck``). The vertices of every creased edge, grown by ``RINGS`` rings, are smoothed
(``puppet.runtime.skinsmoothing``), except where FAPs place the skin exactly: the feature points
and the lid margins keep their own motion. The lip lines' points between the lips' feature points
(interpolated) are smoothed with the skin round them: kept apart, ICT creased 990 more edges, most
at the lips.

Once is enough: on ICT a second round (the poses checked again on the smoothed face, the vertices
around what still creased added) smoothed 550 more vertices and creased 460 more edges. What the
first leaves creased lies inside what it smooths, where more smoothing moves a crease rather than
ending it.

On the ICT head rigged by transfer (26,719 vertices; its edges about half the default face's) it
smooths 8,166 vertices, and the edges creased over the 21 poses within the fold limits fall from
15,593 to 4,632, with no fold. The default face's shipped rig lists none, and so does the
default face written as a bare mesh and rigged by transfer: its mesh is the reference's.
"""

from __future__ import annotations

import numpy as np

from puppet.runtime.forked import forked_map
from puppet.runtime.posecheck import PoseCheck
from puppet.runtime.runtime import Runtime
from puppet.runtime.skinsmoothing import grown, neighbours

RINGS = 2
"""Rings of neighbours around a creased edge's vertices that are smoothed with them."""

FINER = 0.7
"""A face is smoothed where its mesh is finer than the reference's: its edges' hinges, at the median,
under this share of the reference's at the same place (``PoseCheck.fineness``; ICT: 0.47). There a
crease is a hinge that the coarser reference spreads over a longer edge, and smoothing spreads it
alike. On a mesh as coarse, a crease is the motion's own, and smoothing only moves it: the
default face written as a bare mesh and rigged by transfer creased 121 more edges with ten
vertices smoothed, a face of the shape model (the default face's mesh, reshaped) 128 more with
35, where its edges were locally finer."""


def crease_smoothed(runtime: Runtime, reference: Runtime) -> Runtime:
    """A copy of ``runtime`` (``Runtime.with_smoothing``, with a sliver guard) whose rig's
    ``smoothed`` vertices are found as the module says. ``reference``: the default face's runtime,
    which bounds the bends. Both may be built without their sliver guards (``Runtime(...,
    guard=False)`` saves a second on the ICT head): the check only chooses where to smooth, and the
    guard, which holds a few triangles at the eye corners, changes which edges crease there a little
    (74 of the bare default face's 21-pose total); the copy returned has its guard again."""
    check = PoseCheck(runtime.face, reference)
    if np.median(check.fineness) >= FINER:
        return runtime.with_smoothing(np.zeros(0, dtype=np.int64))
    adjacency = neighbours(check.triangles, len(runtime.rest))
    around = grown(_vertices(check, _creased_edges(runtime, check)), adjacency, RINGS)
    return runtime.with_smoothing(np.flatnonzero(around & runtime.dffd_vertices & ~_placed(runtime)))


def _creased_edges(runtime: Runtime, check: PoseCheck) -> np.ndarray:
    """Bool mask over ``check``'s edges of those any of its poses creases on ``runtime``, the poses
    checked on every core (``puppet.runtime.forked``)."""
    def creased(name: str) -> np.ndarray:
        return check.creased(name, runtime.deform_faps(**check.poses[name]))

    return np.logical_or.reduce(forked_map(creased, list(check.poses)))


def _vertices(check: PoseCheck, edges: np.ndarray) -> np.ndarray:
    """Bool mask of the vertices of these edges (a mask over ``check``'s)."""
    mask = np.zeros(len(check.rest), dtype=bool)
    mask[check.hinges.edges[edges].ravel()] = True
    return mask


def _placed(runtime: Runtime) -> np.ndarray:
    """Bool mask of the vertices FAPs place exactly: the feature points, and the lid margins' control
    points (a group), which must meet the other lid's in a blink."""
    mask = np.zeros(len(runtime.rest), dtype=bool)
    mask[list(runtime.face.feature_vertices.values())] = True
    held = [p.vertex for p in runtime.rig.control_points if p.vertex is not None and p.group is not None]
    mask[np.asarray(held, dtype=np.int64)] = True
    return mask
