"""What the shipped UR robot program asks of its controller, read from its own header.

``robot-programs/ur/station_link.script`` states in its header the controller software it needs
(``# NEEDS PolyScope 5.15+ (make_list, ...)``: ``make_list``, Script Directory §16.10, came with
PolyScope 5.15's lists) and in its configuration the register window it serves (``global BASE =
128``, UR's general-purpose registers). ``station check`` prints the first when the configured
window is the second; the numbers live in the program only, so the two never disagree.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

__all__ = ["UR_PROGRAM", "ProgramNeeds", "ur_program_needs"]

#: the shipped UR program (present in a checkout of the station, not in an installed wheel)
UR_PROGRAM = Path(__file__).resolve().parents[2] / "robot-programs" / "ur" / "station_link.script"

_NEEDS = re.compile(r"^#\s*NEEDS\s+(?P<software>\S+)\s+(?P<version>\d+(?:\.\d+)*)\+\s*\((?P<why>[^)]*)\)", re.M)
_BASE = re.compile(r"^\s*global\s+BASE\s*=\s*(?P<base>\d+)\s*$", re.M)


@dataclass(frozen=True)
class ProgramNeeds:
    """The program's own statement: the controller software and its minimum version, why, and
    the first register of the map's window it serves."""

    path: Path
    software: str  # "PolyScope"
    version: str  # the minimum, "5.15"
    why: str  # the header's reason, "make_list, §16.10, came with 5.15's lists"
    register_base: int

    def line(self) -> str:
        return f"{self.path.name} needs {self.software} {self.version} or later ({self.why})"


def ur_program_needs(path: Path = UR_PROGRAM) -> ProgramNeeds | None:
    """The UR program's needs as its header states them; None where the program is not there
    (an installed station without the repository's robot-programs/) or states none."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError:
        return None
    needs, base = _NEEDS.search(text), _BASE.search(text)
    if needs is None or base is None:
        return None
    return ProgramNeeds(path, needs["software"], needs["version"], needs["why"].strip(), int(base["base"]))
