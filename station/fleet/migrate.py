"""The fleet store's schema: an ordered set of plain SQL migrations (``migrations/NNNN_*.sql``),
applied in order, each in its own transaction, and recorded in ``fleet_schema_version``.

Run by the plant's database administrator (``station fleet --migrate``), never by a station or
the dashboard: creating the tables and the two group roles needs the database's owner. Two
administrators migrating at once are serialised by an advisory lock.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from importlib import resources

import psycopg

__all__ = ["Migration", "migrations", "latest_version", "current_version", "migrate"]

#: advisory lock key: 'FLEETMIG' as an integer (any constant the plant's other tools do not use)
_LOCK_KEY = 0x464C_4545_544D_4947

_VERSION_TABLE = """CREATE TABLE IF NOT EXISTS fleet_schema_version (
    version     INTEGER PRIMARY KEY,
    name        TEXT NOT NULL,
    applied_utc TIMESTAMPTZ NOT NULL DEFAULT now()
)"""


@dataclass(frozen=True)
class Migration:
    version: int
    name: str
    sql: str


def migrations() -> list[Migration]:
    """The package's migrations in order; their numbers run 1, 2, 3 … without a gap."""
    found = []
    for entry in resources.files("station.fleet").joinpath("migrations").iterdir():
        m = re.fullmatch(r"(\d{4})_([a-z0-9_]+)\.sql", entry.name)
        if m:
            found.append(Migration(int(m.group(1)), m.group(2), entry.read_text(encoding="utf-8")))
    found.sort(key=lambda m: m.version)
    if [m.version for m in found] != list(range(1, len(found) + 1)):
        raise RuntimeError(f"fleet migrations are not numbered 1 … n: {[m.version for m in found]}")
    return found


def latest_version() -> int:
    return len(migrations())


def current_version(conn: psycopg.Connection) -> int:
    """The schema version of the store (0: empty, no migration applied)."""
    row = conn.execute("SELECT to_regclass('fleet_schema_version') IS NOT NULL").fetchone()
    if not row or not row[0]:
        return 0
    row = conn.execute("SELECT coalesce(max(version), 0) FROM fleet_schema_version").fetchone()
    return int(row[0]) if row else 0


def migrate(conn: psycopg.Connection, target: int | None = None) -> list[int]:
    """Apply the migrations above the store's version up to ``target`` (default: all); returns
    the versions applied. ``conn`` must be in autocommit mode (each migration is one transaction)."""
    todo = migrations()
    target = len(todo) if target is None else target
    if not 0 <= target <= len(todo):
        raise ValueError(f"no fleet schema version {target} (this station knows 0 … {len(todo)})")
    applied: list[int] = []
    conn.execute("SELECT pg_advisory_lock(%s::bigint)", (_LOCK_KEY,))
    try:
        conn.execute(_VERSION_TABLE)
        for m in todo:
            if m.version > target or m.version <= current_version(conn):
                continue
            with conn.transaction():
                conn.execute(m.sql.encode())  # a whole file: no parameters, so the simple protocol
                conn.execute("INSERT INTO fleet_schema_version (version, name) VALUES (%s, %s)", (m.version, m.name))
            applied.append(m.version)
    finally:
        conn.execute("SELECT pg_advisory_unlock(%s::bigint)", (_LOCK_KEY,))
    return applied
