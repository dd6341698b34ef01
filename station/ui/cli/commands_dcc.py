"""``station export-dcc``: a finished calibration as a Digital Calibration Certificate (issue 41)."""

from __future__ import annotations

import argparse
import sys

from station.cell.records.certificates import record_certificate
from station.cell.records.rundb import RunDB
from station.ui.cli.process.output import write_file


def cmd_export_dcc(args: argparse.Namespace) -> int:
    from station.ui.cli.commands_cell import existing_db
    from station.ui.report.dcc import SCHEMA_VERSION, dcc_for_run, read_issuer

    existing_db(args.db)
    issuer = read_issuer(args.issuer)
    with RunDB(args.db) as db:
        db.run(args.run)  # a clear error for a run that is not there
        text = dcc_for_run(db, args.run, issuer, operator=args.operator)
    write_file(args.output, text.decode("utf-8"))
    record_certificate(args.db, args.run, text, SCHEMA_VERSION)  # what OPC UA and the fleet store offer
    print(f"certificate of run {args.run} written to {args.output} (DCC {SCHEMA_VERSION}, D-SI; validated against "
          f"the kept schema)")
    note = _to_fleet(args.db, args.run)
    if note:
        print(note, file=sys.stderr)
    return 0


def _to_fleet(db: str, run_id: int) -> str | None:
    """The certificate to the fleet store with its run, when the run was published or queued for
    one; a line when it could only be kept for 'station sync'. Never fails the export."""
    from station.cell.publication.certificates import send_certificates
    from station.fleet.settings import fleet_url
    from station.ui.cli.commands_fleet import _queued_url

    url = fleet_url(_queued_url(db, run_id))
    if url is None:
        return None
    try:
        result = send_certificates(db, url, only_run=run_id)
    except Exception as exc:  # noqa: BLE001 - the certificate is written; the fleet gets it on 'station sync'
        return f"fleet: certificate of run {run_id} kept for 'station sync' ({exc})"
    if result.sent:
        return f"fleet: certificate of run {run_id} sent to the fleet store"
    if result.waiting or not result.ok:
        why = result.error or "its run is not in the fleet store yet"
        return f"fleet: certificate of run {run_id} kept for 'station sync --db {db}' ({why})"
    return None
