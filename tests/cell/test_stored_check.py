"""The collision work done once (issue 42): the travel vias memoized by configuration and exact
poses (station/cell/plan/via_memo.py), and the pre-motion check's path stored with the run for the
report's picture (station/cell/plan/path_record.py), read back only where it is the check of the
steps drawn."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import station.cell.plan.vias as vias
from station.cell.config.cell_config import load_config
from station.cell.pipeline.premotion import premotion_check
from station.cell.plan.assembly import Plan
from station.cell.plan.path_record import checked_path_record, stored_path
from station.cell.plan.run_path import plan_path
from station.cell.plan.via_memo import memo_travel_vias

pytestmark = pytest.mark.timeout(600)

CELL = Path(__file__).resolve().parents[2] / "examples/scara600_column/cell.toml"


@pytest.fixture(scope="module")
def checked():
    """The SCARA column example's pre-motion check: the configuration, the check, the checked steps
    and the record the run stores, through JSON as the run database keeps it."""
    cfg = load_config(CELL)
    pre = premotion_check(cfg)
    steps = pre.plan.run_steps(cfg.plan.verification_cycles, False)
    record = checked_path_record(cfg, pre.plan, steps, pre.collision)
    assert record is not None
    return cfg, pre, steps, json.loads(json.dumps(record))


def _same(a, b) -> bool:
    return len(a) == len(b) and all(la == lb and pa == pb and qa.tobytes() == qb.tobytes()
                                    for (qa, la, pa), (qb, lb, pb) in zip(a, b))


def test_a_memoized_move_is_travel_vias_own_answer_and_asked_once(checked, monkeypatch):
    """On a fresh configuration object: the memo's vias equal travel_vias's bit for bit, a second ask
    of the same move does not call it, a pose one ulp away does, and a copy handed out can be changed
    without changing the next answer."""
    cfg = load_config(CELL)
    _c, _pre, steps, _r = checked
    calls = []
    real = vias.travel_vias

    def counted(c, a, b, lifts=None):
        calls.append((a, b))
        return real(c, a, b, lifts)

    monkeypatch.setattr(vias, "travel_vias", counted)
    plan_path(cfg, Plan(tuple(steps), (), ()))
    asked = len(calls)
    assert 0 < asked < len(steps) - 1  # the verification cycles repeat their moves
    around = [(a, b) for a, b in calls if real(cfg, a, b)]
    assert around, "the column example has moves around its column"
    a, b = around[0]
    before = len(calls)
    got = memo_travel_vias(cfg, a, b)
    assert len(calls) == before  # the plan asked this move already
    want = real(cfg, a, b)
    assert [(q.tobytes(), n) for q, n in got] == [(q.tobytes(), n) for q, n in want]
    got[0][0][:] = 0.0
    assert memo_travel_vias(cfg, a, b)[0][0].tobytes() == want[0][0].tobytes()
    memo_travel_vias(cfg, np.nextafter(a, np.inf), b)
    assert len(calls) == before + 1


def test_the_stored_check_reads_back_bit_for_bit_on_a_reloaded_configuration(checked):
    """The report's configuration is another object read from the same text: the record gives the
    poses the check checked (bytes equal to a fresh plan path) and its least clearance."""
    cfg, pre, steps, record = checked
    again = load_config(CELL)
    hit = stored_path(again, steps, record)
    assert hit is not None
    poses, report = hit
    assert _same(poses, plan_path(cfg, pre.plan))
    want = pre.collision
    assert (report.closest, report.closest_touch, report.margin_mm) == (want.closest, want.closest_touch, want.margin_mm)
    assert (report.poses, report.samples, report.evaluated, report.vias) == (want.poses, want.samples, want.evaluated,
                                                                             want.vias)
    assert report.vias > 0 and report.clash is None


def test_a_record_of_other_steps_or_another_text_is_not_used(checked, tmp_path):
    cfg, _pre, steps, record = checked
    moved = list(steps)
    s = moved[3]
    moved[3] = type(s)(s.index, s.kind, s.point, s.point_id, s.elbow, s.direction, s.cycle,
                       (np.nextafter(s.joints[0], np.inf), *s.joints[1:]))
    assert stored_path(cfg, moved, record) is None
    assert stored_path(cfg, steps[:-1], record) is None
    text = CELL.read_text(encoding="utf-8")
    other = tmp_path / "cell.toml"
    other.write_text(text + "\n# an edit\n", encoding="utf-8")
    for f in CELL.parent.iterdir():  # the files the cell names, beside it
        if f.name != "cell.toml" and f.is_file():
            (tmp_path / f.name).write_bytes(f.read_bytes())
    assert stored_path(load_config(other), steps, record) is None
    assert stored_path(cfg, steps, {**record, "poses": record["poses"][:-1]}) is None
    assert stored_path(cfg, steps, None) is None


def test_the_picture_from_the_record_is_the_picture_checked_anew(checked):
    """The report's picture drawn from the record is byte for byte the one that plans and checks
    the path again (on a configuration object of its own, as ``station report`` has)."""
    from station.ui.report.render.cell_picture import run_picture, stored_check

    _cfg, _pre, steps, record = checked
    again = load_config(CELL)
    with stored_check(record):
        from_record = run_picture(again, steps).svg
    assert from_record == run_picture(load_config(CELL), steps).svg
