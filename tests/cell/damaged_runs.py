"""Helpers of the damaged-record tests: a copy of the good run database with some SQL applied,
and the CLI's exit code and output."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

from station.ui.cli.main import main


def damaged(good_db: Path, tmp_path: Path, sql: str) -> Path:
    db = tmp_path / "runs.sqlite"
    shutil.copy(good_db, db)
    conn = sqlite3.connect(db)
    conn.executescript(sql)
    conn.close()
    return db


def run_cli(capsys, *argv: object) -> tuple[int, str]:
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out + out.err
