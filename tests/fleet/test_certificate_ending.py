"""A certificate goes to the fleet with the ending it certifies (issue 41): a run resumed after its
first ending is a new publication (a new UUID); a certificate exported after the resume waits for
that publication to reach the store, never lands on the earlier ending's, and one exported before
the resume stays with the ending it was made from."""

from __future__ import annotations

import sqlite3

from fleet_runs import example_config, finished_run

from station.cell.publication.certificates import _todo
from station.cell.publication.outbox import enqueue_run
from station.cell.records.certificates import record_certificate
from station.cell.records.run_records import utc_now
from station.cell.records.rundb import RunDB


def _sent(db, run_uuid: str) -> None:
    """The outbox row marked as in the store (what a successful sync writes)."""
    with sqlite3.connect(str(db)) as conn:
        conn.execute("UPDATE fleet_outbox SET sent_utc = ? WHERE run_uuid = ?", (utc_now(), run_uuid))


def _end_again(db, run_id: int) -> None:
    """The run's summary stored again, later: what a resume that ends again writes."""
    with RunDB(db) as rdb:
        rdb.save_result(run_id, "summary", rdb.load_result(run_id, "summary"))  # stamped now (µs)


def _run(tmp_path):
    """A finished run's database (its summary stored), and its id."""
    db = tmp_path / "runs.sqlite"
    return db, finished_run(db, example_config())


def test_a_certificate_exported_after_a_resume_waits_for_that_ending(tmp_path):
    db, run_id = _run(tmp_path)
    cfg = example_config()
    first = enqueue_run(db, run_id, cfg)
    _sent(db, first)
    _end_again(db, run_id)
    second = enqueue_run(db, run_id, cfg)
    assert second != first  # the new ending is a new publication
    record_certificate(db, run_id, b"<dcc>after the resume</dcc>", "3.1.2")
    assert [t[4] for t in _todo(db, run_id)] == [None]  # waits: not on the first ending's UUID
    _sent(db, second)
    assert [t[4] for t in _todo(db, run_id)] == [second]


def test_a_certificate_exported_before_a_resume_stays_with_its_ending(tmp_path):
    db, run_id = _run(tmp_path)
    cfg = example_config()
    first = enqueue_run(db, run_id, cfg)
    record_certificate(db, run_id, b"<dcc>the first ending</dcc>", "3.1.2")
    _end_again(db, run_id)
    second = enqueue_run(db, run_id, cfg)
    _sent(db, second)
    assert [t[4] for t in _todo(db, run_id)] == [None]  # its own ending is not in the store yet
    _sent(db, first)
    assert [t[4] for t in _todo(db, run_id)] == [first]


def test_a_certificate_table_from_before_the_ending_column_is_read_as_before(tmp_path):
    db, run_id = _run(tmp_path)
    first = enqueue_run(db, run_id, example_config())
    _sent(db, first)
    with sqlite3.connect(str(db)) as conn:  # the table as stop 45 wrote it
        conn.execute("CREATE TABLE certificates (run_id INTEGER PRIMARY KEY, schema_version TEXT NOT NULL, "
                     "sha256 TEXT NOT NULL, xml BLOB NOT NULL, written_utc TEXT NOT NULL, fleet_sent_utc TEXT)")
        conn.execute("INSERT INTO certificates VALUES (?, '3.1.2', 'x', x'00', ?, NULL)", (run_id, utc_now()))
    assert [t[4] for t in _todo(db, run_id)] == [first]
