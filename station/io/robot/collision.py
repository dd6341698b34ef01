"""The ``[collision]`` table of a TOML robot file (issue 40; docs/robot-file.md "Collision shapes"):
the radius of every link's capsule and the pairs of links allowed to touch.

A DH or MDH file has no such table: its links get the default radii
(:func:`station.cell.plan.collision_shapes.default_radii`). A URDF's links get their ``<collision>`` shapes
(:mod:`station.io.robot.urdf_collision`), a link without one the default capsule. The table's keys
and types are checked with the rest of the file (:mod:`station.io.robot.schema`); here its values are checked against the robot.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from station.errors import ConfigError
from station.io.robot.urdf_collision import LinkGeometry

__all__ = ["CollisionSpec", "read_collision"]


@dataclass(frozen=True)
class CollisionSpec:
    """``radius_mm``: one radius per link (the base, then one per joint transform), or None for the
    defaults; ``allowed_pairs``: pairs of link names (the set-up transform's name for the base, a
    joint transform's for the link it moves) never checked against each other; ``geometry``: a URDF's
    ``<collision>`` shapes (:class:`station.io.robot.urdf_collision.LinkGeometry`), used instead of
    those links' capsules."""

    radius_mm: tuple[float, ...] | None = None
    allowed_pairs: tuple[tuple[str, str], ...] = ()
    geometry: tuple[LinkGeometry, ...] = ()


def read_collision(name_or_path: str | Path, link_names: tuple[str, ...]) -> CollisionSpec:
    """The ``[collision]`` table of a TOML robot file, checked against its links ``link_names``
    (base first); a URDF's ``<collision>`` shapes; an empty spec for other formats, the built-in names or a file without the table."""
    path = Path(str(name_or_path))
    if path.suffix == ".urdf" and path.is_file():
        from station.io.robot.urdf_collision import urdf_link_geometry

        return CollisionSpec(geometry=urdf_link_geometry(path))
    if path.suffix != ".toml" or not path.is_file():
        return CollisionSpec()
    with path.open("rb") as f:
        try:
            raw = tomllib.load(f).get("collision")
        except tomllib.TOMLDecodeError:
            return CollisionSpec()  # the robot file's own reader has reported the syntax already
    if raw is None:
        return CollisionSpec()
    src = f"{path}: [collision]"
    radii = raw.get("radius_mm")
    if radii is not None:
        ok = isinstance(radii, list) and len(radii) == len(link_names) and all(
            isinstance(r, (int, float)) and not isinstance(r, bool) and math.isfinite(r) and 0 < r <= 2000
            for r in radii)
        if not ok:
            raise ConfigError(f"{src}.radius_mm must give one radius in (0, 2000] mm per link ({len(link_names)}: "
                              f"{', '.join(link_names)}), got {radii!r}")
    pairs = []
    for pair in raw.get("allowed_pairs", []):
        bad = [n for n in pair if n not in link_names]
        if bad or len(pair) != 2:
            raise ConfigError(f"{src}.allowed_pairs: {pair!r} must name two links of {', '.join(link_names)}")
        pairs.append((str(pair[0]), str(pair[1])))
    return CollisionSpec(None if radii is None else tuple(float(r) for r in radii), tuple(pairs))
