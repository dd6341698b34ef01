"""Where each probe's tip really touches the cube: the simulated head's readings, written from
``docs/probe-head.md`` ("Frames and conventions"), not from the station's solver.

The station turns readings into the cube's pose with :mod:`station.core.probe.geometry`; if the
simulator produced its readings with the same module, a slip in it (a face's normal, a sign of the
tip radius, the frame a direction is given in) would be made twice and cancel, and every
end-to-end test would pass (issue 33, item 7). This is the same physics derived again, a
different way: each probe is carried into the cube's frame and its tip sphere is moved along its
axis until it rests on its face plane, one probe at a time, in plain vector arithmetic.
``tests/simulators/test_probe_contact.py`` holds the two to each other and to the document.

The document's conventions:

* MKKS is the head frame; MPKS the cube-corner frame, origin on a top corner, the cube in
  ``x ≥ 0, y ≥ 0, z ≤ 0``; faces ``top`` (z = 0, outward +z), ``x`` (x = 0, outward −x),
  ``y`` (y = 0, outward −y), each an ``E × E`` square of the cube's edge ``E``.
* A probe has a mounting point ``b`` (the tip-sphere centre at reading 0, in MKKS) and a unit
  direction ``d`` towards its face; reading ``s`` puts the tip-sphere centre at ``b + s·d``. A
  reading is valid within ``±stroke/2`` (beyond: over or under range).
* ``M`` is the pose of MPKS in MKKS.

What the document leaves to physics, stated here: the tip rests on the face where the sphere of
radius ``ρ`` is tangent to the face plane from outside; it touches the face only where that
tangent point lies on the face's square; a plunger whose axis meets its face at a grazing angle
(cosine below 0.14, about 8°) slides off instead of reading, and so does one pointing away from
the face: no reading (NaN).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["touch_readings", "FACES", "GRAZING_COSINE"]

#: (outward normal, the two in-face axes, their ranges as multiples of the edge), by face index
#: (0 top, 1 x face, 2 y face), from docs/probe-head.md "Frames and conventions"
FACES = (
    ((0.0, 0.0, 1.0), ((0, (0.0, 1.0)), (1, (0.0, 1.0)))),    # top: z = 0, 0 ≤ x, y ≤ E
    ((-1.0, 0.0, 0.0), ((1, (0.0, 1.0)), (2, (-1.0, 0.0)))),  # x face: x = 0, 0 ≤ y ≤ E, −E ≤ z ≤ 0
    ((0.0, -1.0, 0.0), ((0, (0.0, 1.0)), (2, (-1.0, 0.0)))),  # y face: y = 0, 0 ≤ x ≤ E, −E ≤ z ≤ 0
)
#: a plunger meeting its face more obliquely than this (|cos| of the angle to the normal) slides
GRAZING_COSINE = 0.14


def touch_readings(mounts: np.ndarray, directions: np.ndarray, faces: np.ndarray, tip_radii: np.ndarray,
                   strokes: np.ndarray, edge_mm: float, M: np.ndarray) -> np.ndarray:
    """Exact readings ``(n,)`` [mm] of probes ``mounts (n, 3)`` [mm, MKKS], ``directions (n, 3)``
    (unit, MKKS), on ``faces (n,)``, with tip radii and strokes ``(n,)`` [mm], for the cube of edge
    ``edge_mm`` whose corner frame stands at ``M (4, 4)`` in MKKS: +inf over range, -inf under
    range, NaN where the probe does not rest on its face."""
    R, t = np.asarray(M, dtype=float)[:3, :3], np.asarray(M, dtype=float)[:3, 3]
    out = np.empty(len(mounts))
    for i in range(len(mounts)):
        # the probe in the cube's frame: x_cube = Rᵀ (x_head − t)
        b = R.T @ (np.asarray(mounts[i], dtype=float) - t)
        d = R.T @ np.asarray(directions[i], dtype=float)
        normal, spans = FACES[int(faces[i])]
        n = np.array(normal)
        rho = float(tip_radii[i])
        along = float(n @ d)  # the axis against the outward normal: negative when it points at the face
        if not along < -GRAZING_COSINE:
            out[i] = math.nan
            continue
        # the sphere rests on the plane n·x = 0 from outside: n·(b + s d) = ρ
        s = (rho - float(n @ b)) / along
        tangent = b + s * d - rho * n
        on_face = all(lo * edge_mm <= tangent[axis] <= hi * edge_mm for axis, (lo, hi) in spans)
        if not on_face:
            out[i] = math.nan
        elif s > strokes[i] / 2.0:
            out[i] = math.inf
        elif s < -strokes[i] / 2.0:
            out[i] = -math.inf
        else:
            out[i] = s
    return out
