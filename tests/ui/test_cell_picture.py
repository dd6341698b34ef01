"""The picture of the cell with the plan's poses (issue 40): ``station plan CONFIG --out DIR`` writes
``cell.svg`` and ``cell.png``, says where in its text and JSON, and the SVG shows what the plan holds.

The SVG is read back as a person reads the drawing: its markers counted per pose family against the
plan's steps in ``station plan --json``, and a shape's place measured against the axes' own tick
labels (the tick marks' positions and their numbers), not against the module's transforms.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import tomllib
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.plan.steps import PlannedStep, StepKind
from station.ui.cli.main import main
from station.ui.report.render.cell_picture import PNG_NAME, SVG_NAME, family_id, run_picture

pytestmark = pytest.mark.timeout(600)

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = {"scara600_column": ROOT / "examples/scara600_column/cell.toml",
            "puma560_obstacles": ROOT / "examples/puma560_obstacles/cell.toml"}
SVG = "{http://www.w3.org/2000/svg}"
XLINK = "{http://www.w3.org/1999/xlink}href"


@pytest.fixture(scope="module", params=sorted(EXAMPLES))
def planned(request, tmp_path_factory):
    """``station plan EXAMPLE --out DIR --json``: its JSON object, the folder and the SVG's tree."""
    out = tmp_path_factory.mktemp(request.param)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["plan", str(EXAMPLES[request.param]), "--out", str(out / "plan"), "--json"])
    assert code == 0
    doc = json.loads(buf.getvalue().strip().splitlines()[-1])
    return request.param, doc, out / "plan", ET.parse(out / "plan" / SVG_NAME).getroot()


def _group(root: ET.Element, gid: str) -> ET.Element:
    found = [e for e in root.iter(f"{SVG}g") if e.get("id") == gid]
    assert len(found) == 1, f"{gid}: {len(found)} groups"
    return found[0]


def _markers(root: ET.Element, gid: str) -> int:
    return len(list(_group(root, gid).iter(f"{SVG}use")))


def test_plan_writes_the_picture_and_says_where(planned):
    _name, doc, folder, _root = planned
    assert doc["picture"] == {"svg": str(folder / SVG_NAME), "png": str(folder / PNG_NAME)}
    png = (folder / PNG_NAME).read_bytes()
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and len(png) > 10_000


def test_one_marker_per_step_in_each_view_per_pose_family(planned):
    name, doc, _folder, root = planned
    families = Counter(s["elbow"] for s in doc["steps"])
    assert sum(families.values()) == len(doc["steps"]) > 100
    for view in ("top", "side"):
        for code, n in families.items():
            assert _markers(root, f"{view}-touches-{family_id(code)}") == n, (name, view, code)
        drawn = {g.get("id") for g in root.iter(f"{SVG}g") if (g.get("id") or "").startswith(f"{view}-touches-")}
        assert drawn == {f"{view}-touches-{family_id(c)}" for c in families}
        # the via poses the collision check counted, each drawn
        vias = doc["collision"]["vias"]
        assert (_markers(root, f"{view}-vias") if vias else 0) == vias
    assert doc["collision"]["vias"] > 0  # both examples go round their obstacles


def test_every_obstacle_is_drawn_in_both_views(planned):
    name, _doc, _folder, root = planned
    cell = tomllib.loads(EXAMPLES[name].read_text())
    for view in ("top", "side"):
        ids = [g.get("id") or "" for g in root.iter(f"{SVG}g")]
        for ob in cell["obstacle"]:
            hits = [i for i in ids if re.fullmatch(rf"{view}-obstacle-\d+-obstacle_{ob['name']}_", i)]
            assert len(hits) == 1, (name, view, ob["name"])
            assert _group(root, hits[0]).find(f"{SVG}path").get("d").startswith("M ")
        assert any(i.startswith(f"{view}-cube-") for i in ids)


def _ticks(axes: ET.Element, which: str) -> tuple[np.ndarray, np.ndarray]:
    """The axis' tick marks: their pixel positions (x for X ticks, y for Y ticks) and their labels' values."""
    axes_groups = [g for g in axes if (g.get("id") or "").startswith("matplotlib.axis_")]  # X, then Y
    axis = axes_groups[0 if which == "x" else 1]
    pix, val = [], []
    for tick in axis:
        if not re.fullmatch(rf"{which}tick_\d+", tick.get("id") or ""):
            continue
        mark = next(tick.iter(f"{SVG}use"))
        text = "".join(next(tick.iter(f"{SVG}text")).itertext()).replace("\u2212", "-")
        pix.append(float(mark.get(which)))
        val.append(float(text))
    assert len(pix) >= 3
    return np.array(pix), np.array(val)


def _to_mm(axes: ET.Element, px: float, py: float) -> tuple[float, float]:
    """A pixel of the view in mm, from the ticks: a straight line through (pixel, label) pairs."""
    out = []
    for which, p in (("x", px), ("y", py)):
        pix, val = _ticks(axes, which)
        slope, offset = np.polyfit(pix, val, 1)
        assert np.allclose(slope * pix + offset, val, atol=1e-6 * np.ptp(val))  # the ticks are linear
        out.append(slope * p + offset)
    return out[0], out[1]


def _path_points(el: ET.Element) -> np.ndarray:
    d = el.find(f"{SVG}path").get("d")
    return np.array([float(v) for v in re.findall(r"-?\d+(?:\.\d+)?", d)]).reshape(-1, 2)


def test_each_obstacle_stands_where_the_cell_file_puts_it(planned):
    """Each obstacle's centre read off both views (the middle of its outline, in mm by the ticks) is
    its pose in the body frame less the robot's set-up (no rotation in either), and its outline is as
    wide (from above) and as tall (from the side) as the cell file says: scara600_column's column,
    puma560_obstacles' column and fixture post."""
    name, _doc, _folder, root = planned
    cell = tomllib.loads(EXAMPLES[name].read_text())
    setup = np.array(cell["robot"]["setup"])
    assert not np.any(setup[3:])
    for ob in cell["obstacle"]:
        assert ob["frame"] == "body" and not np.any(ob["pose"][3:])
        want = np.array(ob["pose"][:3]) - setup[:3]  # the base frame: the body frame shifted by the set-up
        width = 2 * ob["radius_mm"] if ob["shape"] == "cylinder" else ob["size_mm"][0]
        height = ob["height_mm"] if ob["shape"] == "cylinder" else ob["size_mm"][2]
        for view, (i, j) in (("top", (0, 1)), ("side", (0, 2))):
            axes = _group(root, f"{view}-view")
            (gid,) = [g.get("id") for g in axes.iter(f"{SVG}g")
                      if re.fullmatch(rf"{view}-obstacle-\d+-obstacle_{ob['name']}_", g.get("id") or "")]
            pts = _path_points(_group(axes, gid))
            lo, hi = (np.array(_to_mm(axes, *p)) for p in (pts.min(axis=0), pts.max(axis=0)))
            assert (lo + hi) / 2 == pytest.approx((want[i], want[j]), abs=1.0), (name, ob["name"], view)
            assert abs(hi[0] - lo[0]) == pytest.approx(width, abs=1.0)
            if view == "side":
                assert abs(hi[1] - lo[1]) == pytest.approx(height, abs=1.0)


def test_the_least_clearance_is_annotated_with_its_pair(planned):
    name, doc, _folder, root = planned
    title = " ".join("".join(t.itertext()) for t in _group(root, "least-clearance").iter(f"{SVG}text"))
    closest = doc["collision"]["closest"]
    if closest is None:
        assert f"over {2 * doc['collision']['margin_mm']:g} mm everywhere" in title
    else:
        assert f"least clearance {closest['clearance_mm']:.1f} mm" in title
        assert closest["a"] in title and closest["b"] in title
        for view in ("top", "side"):
            assert _markers(root, f"{view}-least") == 1
            # the pair's closest points, joined: no farther apart in the view (mm, by the ticks) than
            # the clearance the check reports (a projection is no longer than the segment; the picture
            # samples the move more finely than the check, so it may find them a little closer)
            axes = _group(root, f"{view}-view")
            ends = [np.array(_to_mm(axes, *p)) for p in _path_points(_group(axes, f"{view}-least-pair"))]
            assert len(ends) == 2 and np.linalg.norm(ends[1] - ends[0]) <= closest["clearance_mm"] + 0.05


def test_the_stored_plan_draws_the_same_picture_byte_for_byte(planned):
    """What the report draws from a run's stored steps is the plan's own picture: the same poses,
    the same clearance, the same bytes (no date, fixed ids)."""
    name, doc, folder, _root = planned
    if name != "scara600_column":
        pytest.skip("one example is enough: the drawing is the same code")
    cfg = load_config(EXAMPLES[name])
    steps = [PlannedStep(s["index"], StepKind(s["kind"]), cfg.point_ids.index(s["point_id"]), s["point_id"],
                         s["elbow"], s["direction"], s["cycle"], tuple(s["joints"])) for s in doc["steps"]]
    assert run_picture(cfg, steps).svg == (folder / SVG_NAME).read_text(encoding="utf-8")


def test_a_file_for_the_folder_is_refused_before_planning(tmp_path, capsys):
    blocker = tmp_path / "plan"
    blocker.write_text("")
    assert main(["plan", str(EXAMPLES["scara600_column"]), "--out", str(blocker)]) == 2
    err = capsys.readouterr().err
    assert "that is a file; give a folder" in err and "Traceback" not in err


def test_the_run_report_shows_the_cell_with_the_runs_steps(seed1_run):
    """The report of the built-in cell's seed-1 calibration embeds the picture (an SVG data URI in the
    'cell' section): one marker per step of the stored plan in each view, the simulation's reference
    verification left out (the collision check's plan has none)."""
    import base64

    from station.cell.records.reading.stored_config import stored_plan
    from station.cell.records.rundb import RunDB

    html = (seed1_run.report / "report.html").read_text(encoding="utf-8")
    section = html[html.index('<section id="cell">'):]
    uri = re.search(r'src="data:image/svg\+xml;base64,([^"]+)"', section[:section.index("</section>")]).group(1)
    root = ET.fromstring(base64.b64decode(uri))
    with RunDB(seed1_run.db) as db:
        steps = [s for s in stored_plan(db, 1) if s.kind is not StepKind.REFERENCE]
    families = Counter(s.elbow for s in steps)
    assert len(steps) > 100 and len(families) == 2
    for view in ("top", "side"):
        for code, n in families.items():
            assert _markers(root, f"{view}-touches-{family_id(code)}") == n


def test_a_picture_that_cannot_be_drawn_is_a_note_not_a_lost_report(seed1_run, monkeypatch):
    """The rest of the report stands: the notes say why there is no picture, the section is left out."""
    from station.cell.records.rundb import RunDB
    from station.ui.report import run as report_run
    from station.ui.report.render.html_page import render_html

    def broken(cfg, steps):
        raise ValueError("no shapes for this cell")

    monkeypatch.setattr(report_run, "run_picture", broken)
    with RunDB(seed1_run.db) as db:
        data = report_run.report_data_for_run(db, 1)
    assert data.cell_svg is None
    assert "no picture of the cell (ValueError: no shapes for this cell)" in data.notes
    html = render_html(data)
    assert '<section id="cell">' not in html and "no picture of the cell" in html


def test_the_plan_without_the_upload_draws_its_own_steps(tmp_path, capsys):
    """``--no-upload``: the picture holds that plan's steps (no verification after the correction)
    and the least clearance of those poses, checked for them."""
    assert main(["plan", str(EXAMPLES["scara600_column"]), "--no-upload", "--out", str(tmp_path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert not any(s["kind"] == StepKind.VERIFY_AFTER.value for s in doc["steps"])
    root = ET.parse(tmp_path / SVG_NAME).getroot()
    for code, n in Counter(s["elbow"] for s in doc["steps"]).items():
        assert _markers(root, f"top-touches-{family_id(code)}") == n
    title = " ".join("".join(t.itertext()) for t in _group(root, "least-clearance").iter(f"{SVG}text"))
    poses = int(re.search(r"(\d+) poses and the paths", title).group(1)) if "everywhere" in title else None
    assert poses is None or poses < doc["collision"]["poses"]  # fewer poses than the run with the upload
