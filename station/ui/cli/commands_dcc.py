"""``station export-dcc``: a finished calibration as a Digital Calibration Certificate (issue 41)."""

from __future__ import annotations

import argparse

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
    print(f"certificate of run {args.run} written to {args.output} (DCC {SCHEMA_VERSION}, D-SI; validated against "
          f"the kept schema)")
    return 0
