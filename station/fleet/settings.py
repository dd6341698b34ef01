"""Where the fleet store is: ``STATION_FLEET_URL``, else ``[fleet] url`` (no psycopg here: a
run's end reads this without loading the database driver when no store is configured)."""

from __future__ import annotations

import os

__all__ = ["ENV_URL", "fleet_url"]

ENV_URL = "STATION_FLEET_URL"


def fleet_url(configured: str | None = None) -> str | None:
    """The fleet store's URL: ``STATION_FLEET_URL`` if set, else ``[fleet] url``; None: none."""
    return os.environ.get(ENV_URL) or configured or None
