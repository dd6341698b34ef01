"""A run's stored error model beyond geometry (issue 30, docs/error-terms.md), read back.

A calibration that kept error terms stores them as the result ``error_model``
(:func:`station.cell.pipeline.terms.error_model_record`): the geometry fitted together
with the terms, the kept families, the terms' values and what their basis is computed from.
Everything that rebuilds what such a run built — the recheck's baseline, a tool's export, the
report's correction table — reads it here; this module sits below all of them (the records
layer), so none imports another to get at it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.core.terms.compensation import JointDelta

__all__ = ["StoredErrorModel", "stored_error_model"]


@dataclass(frozen=True)
class StoredErrorModel:
    """A run's stored error model with terms kept (result ``error_model``): the geometry fitted with
    the terms ``params`` [mm, rad], the kept ``families``, the terms' ``names`` and ``values`` (in
    their units), and what their basis is computed from."""

    params: np.ndarray
    families: tuple[str, ...]
    names: tuple[str, ...]
    values: np.ndarray
    gravity: Any  # station.core.terms.error_model.GravityModel | None
    gear_ratios: tuple[float, ...] | None
    rms_residual_um: float | None

    def joint_delta(self, cfg: CellConfig) -> JointDelta:
        """``Δq(q)`` of the kept terms: drift and backlash at zero, as for any new joints (a session
        folds kept backlash into the joint zeros of ``params``, the side its own moves arrive from)."""
        from station.core.terms.error_model import prediction_basis

        def delta(q: np.ndarray) -> np.ndarray:
            basis, _ = prediction_basis(cfg.model, q, self.families, self.names, self.gravity, self.gear_ratios)
            return basis.joint_delta(self.values)

        return delta


def stored_error_model(cfg: CellConfig, record: Mapping[str, Any] | None) -> StoredErrorModel | None:
    """The stored ``error_model`` result (its fields checked where records are read,
    ``record_fields.check_result_fields``) as a :class:`StoredErrorModel`; None when the run kept no
    term (or stored no error model): its geometric identification is its model. A record of older
    stations without ``gravity`` / ``gear_ratios`` takes the cell's."""
    if not record or not record.get("chosen") or not record.get("terms"):
        return None
    from station.core.terms.error_model import GravityModel

    g = record.get("gravity")
    if g is None:
        gravity = cfg.identification.gravity
    else:
        gravity = GravityModel(gravity=tuple(g["gravity"]), masses=None if g.get("masses") is None else tuple(g["masses"]),
                               com=None if g.get("com") is None else tuple(tuple(c) for c in g["com"]),
                               payload_kg=float(g.get("payload_kg", 0.0)),
                               payload_com=tuple(g.get("payload_com", (0.0, 0.0, 0.0))))
    ratios = record.get("gear_ratios")
    ratios = cfg.identification.gear_ratios if ratios is None else tuple(float(r) for r in ratios)
    rms = record.get("rms_residual_um")
    return StoredErrorModel(params=np.asarray(record["params"], dtype=float), families=tuple(record["chosen"]),
                            names=tuple(str(t["name"]) for t in record["terms"]),
                            values=np.array([float(t["value"]) for t in record["terms"]]),
                            gravity=gravity, gear_ratios=ratios,
                            rms_residual_um=None if rms is None else float(rms))
