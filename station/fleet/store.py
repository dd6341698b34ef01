"""The fleet store on PostgreSQL (psycopg 3): connecting, writing one publication, and the
queries of ``station fleet`` and the dashboard. Every query is parameterised.

Credentials never come from the cell file: the URL names the server and database
(``postgresql://host/fleet`` or ``service=plant``); libpq takes the user and password from the
service file, ``~/.pgpass`` or ``PG*`` environment variables.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from datetime import datetime
from typing import Any

import psycopg
from psycopg.rows import dict_row
from psycopg.types.datetime import TimestamptzLoader
from psycopg.types.json import Jsonb

from station.errors import Outcome, StationError
from station.fleet.migrate import current_version, latest_version
from station.fleet.settings import fleet_url

__all__ = ["FleetStoreError", "fleet_url", "connect", "insert_publication", "insert_report", "robot_keys",
           "latest_runs", "robot_history", "run_detail", "report_html", "recent_rechecks", "store_errors",
           "insert_certificate", "certificate_xml"]

#: seconds to wait for the server: a run's end never waits longer than this on the network
CONNECT_TIMEOUT_S = 5

class FleetStoreError(StationError):
    """The fleet store cannot be reached or refused the operation."""

    outcome = Outcome.DATABASE_ERROR


def connect(url: str, *, read_only: bool = False, check_schema: bool = True,
            autocommit: bool = False) -> psycopg.Connection:
    """A connection to the store; ``read_only``: every transaction is read-only (the dashboard).
    ``check_schema``: refuse a store whose schema this station does not know (older or newer)."""
    try:
        conn = psycopg.connect(url, connect_timeout=CONNECT_TIMEOUT_S, application_name="station",
                               autocommit=autocommit)
    except psycopg.Error as e:
        raise FleetStoreError(f"fleet store {_safe(url)}: cannot connect ({_first_line(e)})") from e
    conn.adapters.register_loader("timestamptz", _LenientTimestamptz)
    try:
        if read_only:  # every transaction of the session, autocommit's included
            conn.execute("SET default_transaction_read_only = on")
            if not conn.autocommit:
                conn.commit()
        if check_schema:
            version, want = current_version(conn), latest_version()
            if not conn.autocommit:
                conn.rollback()
            if version != want:
                raise FleetStoreError(
                    f"fleet store {_safe(url)}: schema version {version}, this station needs {want}; "
                    + ("the administrator runs 'station fleet --migrate'" if version < want
                       else "update the station software"))
    except BaseException:
        conn.close()
        raise
    return conn


class _LenientTimestamptz(TimestamptzLoader):
    """A stored time Python cannot hold ('infinity', a year beyond 9999, a BC date: rows stored
    before schema 4's checks) reads as None, which the readers show as damaged, instead of
    failing the whole query, and with it the fleet page."""

    def load(self, data: Any) -> datetime | None:  # type: ignore[override]
        try:
            return super().load(data)
        except psycopg.DataError:
            return None


@contextmanager
def store_errors(url: str) -> Iterator[None]:
    """psycopg's errors as :class:`FleetStoreError` naming the store (and the role's limits)."""
    try:
        yield
    except psycopg.errors.InsufficientPrivilege as e:
        raise FleetStoreError(f"fleet store {_safe(url)}: {_first_line(e)}: this login's role may not do that (a "
                              f"station's role only inserts runs, the dashboard's only reads)") from e
    except psycopg.Error as e:
        raise FleetStoreError(f"fleet store {_safe(url)}: {type(e).__name__}: {_first_line(e)}") from e


def _first_line(e: BaseException) -> str:
    return (str(e).strip().splitlines() or [type(e).__name__])[0]


def _safe(url: str) -> str:
    """The URL for a message: never a password (which the cell file refuses anyway)."""
    try:
        from psycopg.conninfo import conninfo_to_dict

        d = conninfo_to_dict(url)
    except psycopg.Error:
        return "(unparsable URL)"
    d.pop("password", None)
    return " ".join(f"{k}={v}" for k, v in d.items()) or url


# ------------------------------------------------------------------------------------ writing

_RUN_COLUMNS = ("run_uuid", "robot_key", "robot_serial", "robot_model", "cell", "station", "station_version",
                "local_run_id", "kind", "outcome", "started_utc", "finished_utc", "rms_before_um", "rms_after_um",
                "gain", "ap_max_um", "rp_max_um", "drift_rms_um", "drift_max_um", "tolerance_um",
                "recheck_interval_days", "fingerprint", "detail", "simulated", "operator")

#: what a publication queued before a column existed stands for (schema 4: a queued run of an older
#: station was not simulated as far as it said, and named no operator)
_RUN_DEFAULTS = {"simulated": False, "operator": None}

_INSERT_RUN = (f"INSERT INTO runs ({', '.join(_RUN_COLUMNS)}) VALUES ({', '.join(['%s'] * len(_RUN_COLUMNS))}) "
               "ON CONFLICT DO NOTHING")


def insert_publication(conn: psycopg.Connection, pub: Mapping[str, Any]) -> bool:
    """Insert one run (and its robot, once) in one transaction; True if it was new, False if the
    store already held this run UUID (a retry, or another sync got there first)."""
    values = [Jsonb(pub[c]) if c in ("fingerprint", "detail") else pub[c] if c in pub else _RUN_DEFAULTS[c]
              for c in _RUN_COLUMNS]
    with conn.transaction():
        conn.execute("INSERT INTO robots (robot_key, serial) VALUES (%s, %s) ON CONFLICT DO NOTHING",
                     (pub["robot_key"], pub["robot_serial"]))
        cur = conn.execute(_INSERT_RUN, values)
        return cur.rowcount == 1


def insert_report(conn: psycopg.Connection, run_uuid: str, path: str, html: str) -> bool:
    """Attach a run's report; True if new. The run must be in the store already."""
    with conn.transaction():
        cur = conn.execute("INSERT INTO reports (run_uuid, path, html) VALUES (%s, %s, %s) "
                           "ON CONFLICT DO NOTHING", (run_uuid, path, html))
        return cur.rowcount == 1


def insert_certificate(conn: psycopg.Connection, run_uuid: str, xml: bytes, schema_version: str) -> bool:
    """Attach a run's certificate (its bytes as written); True if new. The run must be in the
    store already; the store checks the digest it is keyed by."""
    digest = hashlib.sha256(xml).hexdigest()
    with conn.transaction():
        cur = conn.execute("INSERT INTO certificates (run_uuid, sha256, schema_version, xml) VALUES (%s, %s, %s, %s) "
                           "ON CONFLICT DO NOTHING", (run_uuid, digest, schema_version, xml))
        return cur.rowcount == 1


# ------------------------------------------------------------------------------------ reading

def robot_keys(conn: psycopg.Connection) -> list[str]:
    return [r[0] for r in conn.execute("SELECT robot_key FROM robots ORDER BY robot_key")]


_SUMMARY_COLUMNS = ("run_uuid::text AS run_uuid, robot_key, robot_serial, robot_model, cell, station, "
                    "station_version, local_run_id, kind, outcome, started_utc, finished_utc, rms_before_um, "
                    "rms_after_um, gain, ap_max_um, rp_max_um, drift_rms_um, drift_max_um, tolerance_um, "
                    "recheck_interval_days, simulated, operator")


def latest_runs(conn: psycopg.Connection, *, include_simulated: bool = False) -> list[dict[str, Any]]:
    """Per robot: its latest calibration attempt (whatever its outcome), latest successful
    calibration, latest recheck and latest simulated run (each a dict or None), one index probe
    each. Simulated runs (rehearsals) count as none of the first three unless ``include_simulated``."""
    real = "" if include_simulated else "AND NOT simulated"
    query = f"""
        SELECT r.robot_key,
               (SELECT to_jsonb(x) FROM (SELECT {_SUMMARY_COLUMNS} FROM runs
                  WHERE robot_key = r.robot_key AND kind = 'calibration' {real}
                  ORDER BY finished_utc DESC LIMIT 1) x) AS last_calibration,
               (SELECT to_jsonb(x) FROM (SELECT {_SUMMARY_COLUMNS} FROM runs
                  WHERE robot_key = r.robot_key AND kind = 'calibration' AND outcome = 'SUCCESS' {real}
                  ORDER BY finished_utc DESC LIMIT 1) x) AS last_good_calibration,
               (SELECT to_jsonb(x) FROM (SELECT {_SUMMARY_COLUMNS} FROM runs
                  WHERE robot_key = r.robot_key AND kind = 'recheck' {real}
                  ORDER BY finished_utc DESC LIMIT 1) x) AS last_recheck,
               (SELECT to_jsonb(x) FROM (SELECT finished_utc, kind, outcome FROM runs
                  WHERE robot_key = r.robot_key AND simulated
                  ORDER BY finished_utc DESC LIMIT 1) x) AS last_simulated
          FROM robots r ORDER BY r.robot_key"""
    with conn.cursor(row_factory=dict_row) as cur:
        rows = cur.execute(query.encode()).fetchall()
    return [dict(r) for r in rows]


def recent_rechecks(conn: psycopg.Connection, robot_key: str, since: datetime | str | None,
                    limit: int = 10, *, include_simulated: bool = False) -> list[dict[str, Any]]:
    """A robot's latest rechecks after ``since`` (its last calibration), newest first."""
    real = "" if include_simulated else "AND NOT simulated "
    with conn.cursor(row_factory=dict_row) as cur:
        return list(cur.execute(
            "SELECT finished_utc, drift_rms_um, tolerance_um, outcome FROM runs WHERE robot_key = %s "
            f"AND kind = 'recheck' {real}AND (%s::timestamptz IS NULL OR finished_utc > %s::timestamptz) "
            "ORDER BY finished_utc DESC LIMIT %s".encode(), (robot_key, since, since, limit)).fetchall())


def robot_history(conn: psycopg.Connection, robot_key: str, limit: int = 2000) -> list[dict[str, Any]]:
    """A robot's runs, oldest first (the newest ``limit``)."""
    with conn.cursor(row_factory=dict_row) as cur:
        rows = cur.execute(
            f"SELECT * FROM (SELECT {_SUMMARY_COLUMNS}, EXISTS (SELECT 1 FROM reports p WHERE p.run_uuid = runs.run_uuid) "
            "AS has_report FROM runs WHERE robot_key = %s ORDER BY finished_utc DESC LIMIT %s) h "
            "ORDER BY finished_utc".encode(), (robot_key, limit)).fetchall()
    return [dict(r) for r in rows]


def run_detail(conn: psycopg.Connection, run_uuid: str) -> dict[str, Any] | None:
    with conn.cursor(row_factory=dict_row) as cur:
        row = cur.execute(f"SELECT {_SUMMARY_COLUMNS}, fingerprint, detail, received_utc FROM runs "
                          "WHERE run_uuid = %s".encode(), (run_uuid,)).fetchone()
    return dict(row) if row else None


def report_html(conn: psycopg.Connection, run_uuid: str) -> str | None:
    row = conn.execute("SELECT html FROM reports WHERE run_uuid = %s", (run_uuid,)).fetchone()
    return str(row[0]) if row else None


def certificate_xml(conn: psycopg.Connection, run_uuid: str) -> bytes | None:
    """A run's certificate as the station wrote it: the latest received; None without one."""
    row = conn.execute("SELECT xml FROM certificates WHERE run_uuid = %s ORDER BY received_utc DESC LIMIT 1",
                       (run_uuid,)).fetchone()
    return bytes(row[0]) if row else None


def fetch_all(conn: psycopg.Connection, sql: str, params: Sequence[Any] = ()) -> list[tuple]:
    """A parameterised query's rows (tests and the benchmark)."""
    return list(conn.execute(sql.encode(), params).fetchall())
