"""The TUI's next step when a run stopped with too few valid identification poses (issue 37).

The pipeline's message (:func:`station.cell.pipeline.invalid_poses.invalid_advice`) sorts the
invalid poses by cause, each with the setting to change and its value. The next-step line says the
same in the UI's keys: which setting to set to what in which file, and whether the one-key continue
can succeed - only where a resume may carry the change: ``[plan] max_residual_um`` (it judges the
stored readings again, :data:`station.cell.records.fingerprint.JUDGING_KEYS`) and cleaned probes (a
resume measures the invalid poses again). ``[plan] recenter_attempts``, ``remeasure_attempts`` and
``[robot] setup`` change how poses are measured: a resume refuses them, so those need a new run.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["TOO_FEW_VALID", "InvalidCauses", "invalid_causes", "invalid_next"]

#: the words of the pipeline's refusal (station/cell/pipeline/calibration.py)
TOO_FEW_VALID = "identification poses are valid"

_RESIDUAL = re.compile(r"set \[plan\] max_residual_um = (?P<v>[0-9.]+) \((?P<n>\d+) valid with it\)")
_STROKE = re.compile(r"(?P<n>\d+) had probes out of their stroke: set \[plan\] recenter_attempts = (?P<v>\d+)")
_NO_POSE = re.compile(r"(?P<n>\d+) gave no pose .*?set \[plan\] remeasure_attempts = (?P<v>\d+)")


@dataclass(frozen=True)
class InvalidCauses:
    """The settings the message names: the bound that makes enough poses valid (and how many),
    the re-centring and re-touch attempts to set; None where the message names no such cause."""

    residual_um: str | None = None
    valid_with_it: int = 0
    recenter_attempts: str | None = None
    remeasure_attempts: str | None = None

    @property
    def needs_new_run(self) -> bool:
        """Probes out of their stroke: what fixes it changes how poses are measured."""
        return self.recenter_attempts is not None


def invalid_causes(message: str) -> InvalidCauses | None:
    """The causes of a too-few-valid-poses refusal; None for any other message."""
    if TOO_FEW_VALID not in message:
        return None
    text = " ".join(message.split())
    r, s, p = _RESIDUAL.search(text), _STROKE.search(text), _NO_POSE.search(text)
    return InvalidCauses(r["v"] if r else None, int(r["n"]) if r else 0, s["v"] if s else None, p["v"] if p else None)


def invalid_next(causes: InvalidCauses, config: str, run: int | None, key: str) -> str:
    """The next-step line for ``causes``: each setting with its value, then how to go on."""
    todo = []
    if causes.residual_um is not None:
        todo.append(f"set [plan] max_residual_um = {causes.residual_um} ({causes.valid_with_it} poses valid with it) "
                    f"if the head's own noise is that large (else clean and check the probes)")
    if causes.recenter_attempts is not None:
        todo.append(f"set [plan] recenter_attempts = {causes.recenter_attempts} (probes out of their stroke), or "
                    f"correct [robot] setup to where the robot stands and give [robot] setup_uncertainty_mm its real "
                    f"size")
    if causes.remeasure_attempts is not None:
        todo.append("clean and check the probes (poses without a pose: the probes disagreed)"
                    + (f", or set [plan] remeasure_attempts = {causes.remeasure_attempts}" if causes.needs_new_run
                       else ""))
    if not todo:
        todo.append("fix what the warnings name (the probes, the body, the set-up)")
    what = ("in " + config + ": " if config else "") + "; ".join(todo)
    if causes.needs_new_run or run is None:
        return f"{what}; then start a new run (s): a resume keeps how the poses were measured, and these change it"
    tail = (f"then press {key}: run #{run} judges the stored readings again and measures again only the poses "
            f"still invalid")
    if causes.remeasure_attempts is not None:
        tail += (f" (or set [plan] remeasure_attempts = {causes.remeasure_attempts} and start a new run (s): a "
                 f"resume keeps how poses are measured)")
    return f"{what}; {tail}"
