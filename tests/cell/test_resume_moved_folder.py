"""A run resumes after its cell folder is moved or copied with unchanged files (issue 37 §4): the
fingerprint holds what the files contain, not where they lay. A rehearsal writes its files' paths
absolute into the run's configuration, so before this a copied folder was refused with "[body],
[head], [robot] changed since"."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from station.cell.config.cell_config import parse_text
from station.cell.records.fingerprint import BY_CONTENT, check_same_cell, current_like, fingerprint
from station.cell.records.reading.stored_config import stored_config
from station.cell.records.rundb import RunDB
from station.errors import ConfigError, Outcome
from station.ui.cli.main import main

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "scara600"


def _cell(folder: Path) -> Path:
    folder.mkdir()
    for name in ("robot.toml", "head.toml", "body.csv"):
        shutil.copy(EXAMPLE / name, folder / name)
    text = (EXAMPLE / "cell.toml").read_text()
    text = text[: text.index("[[tool]]")].replace("repeats = 4", "repeats = 1").replace(
        "verification_cycles = 5", "verification_cycles = 1")
    (folder / "cell.toml").write_text(text)
    return folder / "cell.toml"


@pytest.fixture(scope="module")
def measured(tmp_path_factory) -> Path:
    """A cell folder with run 1 measured and finished (NOT_UPLOADED: --no-upload)."""
    cfg = _cell(tmp_path_factory.mktemp("cell") / "first")
    db = str(cfg.parent / "runs.sqlite")
    assert main(["calibrate", "--simulated", str(cfg), "--db", db, "--no-upload", "--json"]) == int(Outcome.NOT_UPLOADED)
    return cfg.parent


def _stamps(db: Path) -> list[tuple[int, str]]:
    with RunDB(str(db)) as rdb:
        return [(m.step_index, m.t_utc) for m in rdb.measurements(1)]


@pytest.mark.parametrize("how", ["moved", "copied"])
def test_a_run_resumes_in_a_moved_or_copied_folder(measured, tmp_path, capsys, how):
    src = tmp_path / "source"
    shutil.copytree(measured, src)
    dst = tmp_path / "elsewhere" / "cell"
    (shutil.move if how == "moved" else shutil.copytree)(str(src), str(dst))
    assert src.exists() == (how == "copied")
    before = _stamps(dst / "runs.sqlite")
    capsys.readouterr()
    code = main(["calibrate", "--simulated", str(dst / "cell.toml"), "--db", str(dst / "runs.sqlite"),
                 "--no-upload", "--resume", "1", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == int(Outcome.NOT_UPLOADED) == out["exit_code"], out.get("failure")
    assert _stamps(dst / "runs.sqlite") == before  # nothing measured again
    with RunDB(str(dst / "runs.sqlite")) as rdb:  # the run reads its files where they lie now
        cfg = stored_config(rdb, 1)
        assert str(dst) in cfg.source and cfg.model.name == "scara600"
    # the report is rebuilt from the moved run database, its files found beside it
    report = tmp_path / "report"
    assert main(["report", "1", "--db", str(dst / "runs.sqlite"), "--output", str(report)]) == 0
    assert any(report.iterdir())


def test_a_changed_file_in_the_moved_folder_is_still_refused(measured, tmp_path, capsys):
    dst = tmp_path / "cell"
    shutil.copytree(measured, dst)
    body = (dst / "body.csv").read_text().splitlines()
    cells = body[1].split(",")  # the first point after the header
    cells[1] = f"{float(cells[1]) + 0.5:.3f}"  # its x 0.5 mm off: another body
    body[1] = ",".join(cells)
    (dst / "body.csv").write_text("\n".join(body) + "\n")
    capsys.readouterr()
    code = main(["calibrate", "--simulated", str(dst / "cell.toml"), "--db", str(dst / "runs.sqlite"),
                 "--no-upload", "--resume", "1", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == int(Outcome.CONFIG_ERROR)
    assert "body points changed since" in out["failure"]["message"]


def test_the_fingerprint_counts_content_not_paths(tmp_path):
    a, b = _cell(tmp_path / "a"), _cell(tmp_path / "b")

    def absolute(cfg: Path) -> str:  # as a rehearsal writes it: every file named by its absolute path
        text = cfg.read_text()
        for name in ("robot.toml", "head.toml", "body.csv"):
            text = text.replace(f'"{name}"', f'"{cfg.parent / name}"')
        return text

    fa = fingerprint(parse_text(absolute(a), str(a)))
    fb = fingerprint(parse_text(absolute(b), str(b)))
    assert fa == fb and fa[BY_CONTENT[0]] == BY_CONTENT[1]
    assert check_same_cell(fa, fb, 1) == ()
    # a fingerprint stored before issue 37 (paths included) is compared the way it was made
    legacy = fingerprint(parse_text(absolute(a), str(a)), by_content=False)
    assert BY_CONTENT[0] not in legacy
    assert current_like(legacy, parse_text(absolute(a), str(a))) == legacy
    with pytest.raises(ConfigError, match=r"\[body\], \[head\], \[robot\] changed since"):
        check_same_cell(legacy, current_like(legacy, parse_text(absolute(b), str(b))), 1)
