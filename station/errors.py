"""Typed errors of the station. Every message says what to do about it."""


class StationError(Exception):
    """Base of all station errors; the CLI turns these into a message and an exit code."""

    exit_code = 2


class ConfigError(StationError, ValueError):
    """A robot file, cell configuration, measurement file or argument is not usable."""

    exit_code = 2


class IdentificationError(StationError):
    """The identification cannot give a trustworthy result (rank deficiency, divergence)."""

    exit_code = 3


class UnreachableError(StationError, ValueError):
    """A pose the robot cannot reach with the given configuration and limits."""

    exit_code = 4
