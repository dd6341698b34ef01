"""Reading the robot files users bring (TOML, DH/MDH CSV, URDF) into the core's chain model,
and checking them before anything uses them: the schema, physical and unit plausibility, the
``[collision]`` and ``[error_terms]`` tables, a URDF's link masses.

May import: :mod:`station.core`, :mod:`station.errors`, the standard library, numpy and the file
parsers (tomllib, pydantic, xml); never :mod:`station.cell` or :mod:`station.ui`.
"""
