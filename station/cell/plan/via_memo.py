"""The travel vias computed once per move (issue 42): the plan's collision check
(:func:`station.cell.plan.collision.plan_path`), the runner (station/cell/run/runner.py) and the
report's picture of the cell ask :func:`station.cell.plan.vias.travel_vias` about the same moves; a
SCARA's answer costs up to four collision checks of joint-space paths (:func:`station.cell.plan.vias._scara_around`).

Why a hit is safe: :func:`travel_vias` is documented as a function of the configuration and the two
poses alone (so that the check and the runner command the same vias), and the configuration is a
frozen object the caches key on by identity (:class:`~station.cell.config.cell_config.CellConfig`).
The memo keys on that object and on the exact bytes of both poses (and of the lifts, where the plan
passes them): a hit is the answer :func:`travel_vias` gave for bit-identical arguments, so the
runner commands exactly the vias the check checked, never ones computed for a nearby pose. A move
:func:`travel_vias` refuses (:class:`~station.errors.UnreachableError`) is not stored: it is asked
again and refused again. Weak keys: the entries go with the configuration.

What it saves on the built-in SCARA cell (``station calibrate --simulated``): the plan's 249 moves
are 82 distinct ones (the verification cycles repeat theirs), and the report's picture asks the
same. The runner's moves start where the robot measured its touch (the retract from the joints the
controller reports), never bit for bit the plan's pose: they are computed anew (a clear direct move
there is not proof of one a few µm away).
"""

from __future__ import annotations

import weakref

import numpy as np

import station.cell.plan.vias as vias
from station.cell.config.cell_config import CellConfig

__all__ = ["memo_travel_vias"]

#: moves remembered per configuration (a plan's are a few hundred; a runner's measured poses rarely repeat)
MAX_ENTRIES = 20_000

_Key = tuple[object, bytes, bytes, bytes]
_MEMO: weakref.WeakKeyDictionary[CellConfig, dict[_Key, tuple[tuple[np.ndarray, str], ...]]] = \
    weakref.WeakKeyDictionary()


def _bytes(q: np.ndarray | None) -> bytes:
    return b"" if q is None else np.ascontiguousarray(q, dtype=float).tobytes()


def memo_travel_vias(cfg: CellConfig, q_from: np.ndarray, q_to: np.ndarray,
                     lifts: tuple[np.ndarray | None, np.ndarray | None] | None = None) -> list[tuple[np.ndarray, str]]:
    """:func:`~station.cell.plan.vias.travel_vias` of the move, computed once per configuration and
    exact pair of poses (and ``lifts``, and the function itself): the same list of (joints, what
    it is), each joints a fresh copy (a caller may change what it gets)."""
    a, b = np.asarray(q_from, dtype=float), np.asarray(q_to, dtype=float)
    lifted = b"" if lifts is None else b"|".join(b"-" if v is None else _bytes(v) for v in lifts)
    fn = vias.travel_vias  # looked up per call and part of the key: a replaced function (a test's) is asked anew
    key = (fn, _bytes(a), _bytes(b), lifted)
    table = _MEMO.setdefault(cfg, {})
    hit = table.get(key)
    if hit is None:
        if len(table) >= MAX_ENTRIES:  # a long-lived station (the TUI, OPC UA) with one configuration
            table.clear()
        hit = table[key] = tuple((np.array(v, dtype=float), name) for v, name in fn(cfg, a, b, lifts))
    return [(v.copy(), name) for v, name in hit]
