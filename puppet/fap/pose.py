"""``Pose``: the one currency of the face side.

Whatever drives the face (a mapping of a performer's controls, a .fap take, an ARKit stream)
hands the face runtime a Pose: what the face should show at one instant. Renderers, recorders and
exporters consume Poses or the deformed mesh, never device data; ``Runtime.deform_pose`` takes one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Pose:
    """What the face shows at one instant: 68 FAP values (FAPU; index 0 = FAP 1, FAP 1 and 2 left 0),
    FAP 1 and FAP 2 as ``viseme`` (select1, select2, blend) and ``expression`` (select1,
    intensity1, select2, intensity2), and muscle contractions 0..1 by name; ``t_ns`` is the
    newest input it includes (``time.monotonic_ns``), where it comes from one."""

    fap: np.ndarray
    viseme: tuple[float, ...] | None = None
    expression: tuple[float, ...] | None = None
    muscles: dict[str, float] = field(default_factory=dict)
    t_ns: int | None = None

    @classmethod
    def neutral(cls) -> Pose:
        """The face at rest."""
        return cls(np.zeros(68))
