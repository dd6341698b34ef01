"""What the robot's base frame is tied to, in words (issue 36).

Body measurements cannot tell some robot directions from where the body stands: everything the
first joint transform A1 holds (where axis 1 stands in the base frame, its tilt, the zero of
joint 1) and, on a SCARA, every height along the parallel axes. :func:`station.core.identification.identifiability.analyze`
takes the set-up R first, so these directions go to the set-up and the robot's parameters keep
the robot file's values there. This module names them for ``identify``, ``plan`` and the report.
"""

from __future__ import annotations

from station.core.identification.identifiability import Identifiability
from station.core.kinematics.model import RobotModel

#: the base frame's line starts with this (the report picks it out of the fit's notes)
BASE_FRAME_NOTE_PREFIX = "the robot's base frame is the robot file's"

#: the first joint transform's parameters in words (A1 sits before joint 1's motion: its
#: translation is where axis 1 stands in the base frame, its roll and pitch the axis's tilt,
#: its yaw the zero of joint 1)
_A1_WORDS = (((0, 1), "the base origin across axis 1"), ((2,), "the base frame's height along axis 1"),
             ((3, 4), "the tilt of axis 1"), ((5,), "the zero of joint 1"))


def setup_directions(model: RobotModel, ident: Identifiability) -> tuple[str, ...]:
    """The robot's parameters (neither R's nor chosen) that these measurements cannot tell from
    the set-up: those whose effect merges into R's parameters, and the first joint transform's,
    which move the whole robot (no effect at all where the data do not use the set-up: distances)."""
    setup = set(model.param_names[:6])
    a1 = set(model.param_names[6:12])
    merged = {d.name for d in ident.dependencies if any(n in setup for n, _ in d.merges_with)}
    held = set(ident.held)
    return tuple(n for n in model.param_names[6:]
                 if n not in ident.chosen and n not in held and (n in merged or n in a1))


def base_frame_note(model: RobotModel, ident: Identifiability) -> str | None:
    """The line that says which directions are the set-up's and what the base frame is tied to
    (None where R is held: then the robot's base parameters are measured against that set-up)."""
    names = setup_directions(model, ident)
    if not names or any(n in ident.held for n in model.param_names[:6]):
        return None
    a1 = model.param_names[6:12]
    words = [w for idx, w in _A1_WORDS if any(a1[i] in names for i in idx)]
    others = [n for n in names if n not in a1]
    what = ", ".join(words) if words else "the robot's place"
    also = f"; {', '.join(others)} keep theirs too, as these measurements see them only with the set-up" if others else ""
    head = (f"{BASE_FRAME_NOTE_PREFIX}: {what} ({', '.join(n for n in names if n in a1)}) keep "
            f"the file's values{also}. ")
    if all(n in ident.zero_effect for n in model.param_names[:6]):  # distances: no set-up in the data
        return head + "Distances do not see where the robot stands, so a body calibration does not measure them"
    setup = ",".join(model.param_names[:6])
    return (head + "A body calibration cannot tell them from where the body stands, so the set-up R takes them. "
            f"To measure them too, measure the set-up another way and hold it (--fix {setup}, or [identification] fix)")
