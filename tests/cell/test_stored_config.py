"""A run's configuration read back from the run database resolves its relative robot, head and
body files beside the configuration it was read from, whatever the current directory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.records.reading.stored_config import config_source, stored_config
from station.cell.records.rundb import RunDB
from station.errors import ConfigError

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "scara600" / "cell.toml"


def test_stored_config_reads_relative_files_beside_the_original(tmp_path, monkeypatch):
    monkeypatch.chdir(EXAMPLE.parent.parent)  # read as 'scara600/cell.toml', a relative path
    cfg = load_config("scara600/cell.toml")
    with RunDB(str(tmp_path / "runs.sqlite")) as db:
        run_id = db.create_run(cfg.source_text, [], seed=None)
        db.save_result(run_id, "config_source", config_source(cfg))
        bare = db.create_run(cfg.source_text, [], seed=None)  # a run from before the source was stored
        monkeypatch.chdir(tmp_path)  # a report made elsewhere
        back = stored_config(db, run_id)
        assert back.model.name == "scara600"
        np.testing.assert_array_equal(back.body_points, cfg.body_points)
        with pytest.raises(ConfigError, match="robot"):
            stored_config(db, bare)


def test_a_label_is_stored_as_it_is():
    import dataclasses

    cfg = load_config(EXAMPLE)
    assert config_source(cfg) == str(EXAMPLE)
    assert config_source(dataclasses.replace(cfg, source="<simulated cell>")) == "<simulated cell>"


def test_a_recheck_refuses_a_baseline_whose_body_report_was_edited_since(tmp_path):
    """The body report and the head file are files of their own: a recheck compares what they
    held, not only the configuration's text (which names them and does not change)."""
    import shutil

    from station.cell.recheck.measure import check_baseline_cell
    from station.cell.records.fingerprint import fingerprint

    cell = tmp_path / "cell"
    shutil.copytree(EXAMPLE.parent, cell)
    cfg = load_config(cell / "cell.toml")
    with RunDB(str(tmp_path / "runs.sqlite")) as db:
        run_id = db.create_run(cfg.source_text, [], seed=None)
        db.save_result(run_id, "fingerprint", fingerprint(cfg))
        check_baseline_cell(db, run_id, cfg)  # the same cell: accepted
        rows = (cell / "body.csv").read_text().splitlines()
        first = rows[1].split(",")
        first[1] = f"{float(first[1]) + 0.5:g}"  # the CMM re-measured one corner 0.5 mm off
        rows[1] = ",".join(first)
        (cell / "body.csv").write_text("\n".join(rows) + "\n")
        with pytest.raises(ConfigError, match="body points"):
            check_baseline_cell(db, run_id, load_config(cell / "cell.toml"))
