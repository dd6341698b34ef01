"""The report as a sign-off document (issue 20): test conditions, ISO 9283 AP and RP per pose,
acceptance against [verification], traceability (serial, controller, operator, certificates,
software), the signature block, the simulated banner on every page, rounded numbers; and the
configuration, head and body fields they come from."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import pytest
from test_report import make_data
from test_report_html import Page

from station.cell.config.cell_config import parse_text
from station.cell.config.schema import _Simulation
from station.cell.config.template import TEMPLATE
from station.errors import ConfigError
from station.io.body_file import read_body_file
from station.io.head_file import parse_head
from station.ui.report import signoff as so
from station.ui.report.contents import Acceptance, IsoPose, ReportData, TestConditions, Traceability
from station.ui.report.provenance import git_commit, software_rows
from station.ui.report.run import check_operator
from station.ui.report.tables import timestamp_text
from station.ui.report.writer import write_report

ROOT = Path(__file__).resolve().parents[2]

POSES = (IsoPose("C1.b", -1, (23.1691, -316.2232, 100.0), 3, 462.7, 10.9, 3, 3.5, 14.4),
         IsoPose("C1.d", 1, (-23.1691, -0.0001, 100.0), 3, 892.4, 14.0, 3, 12.5, 9.0),
         IsoPose("C2.b", -1, (161.9534, -175.6342, 160.0), 3, 538.1, 31.8, 3, 3.7, 41.0))
CONDITIONS = TestConditions(identification_poses=30, identification_measurements=120, repeats=4,
                            verification_poses=3, verification_cycles=3, speed=0.5, settle_s=0.2, samples=4,
                            load="the probe head 'seven'", load_kg=1.8, warmup="", temperature_c=21.4)
TRACE = Traceability(robot_serial="S600-0042", controller="RC-600 s/n 7781", operator="A. Operator",
                     operator_from="--operator", head="seven", head_file="head.toml",
                     head_certificate_id="CMM-H-17", head_certificate_date="2026-10-28", body="20 measuring points",
                     body_file="body.csv", body_certificate_id="CMM-B-42", body_certificate_date="",
                     software=(("git commit", "0123456789ab"), ("numpy", "2.0")))


def signoff_data(*, simulated: bool = False, max_ap: float | None = 10.0, max_rp: float | None = 40.0) -> ReportData:
    d = make_data()
    return dataclasses.replace(d, created="2026-12-01T23:57:22.702231Z", simulated=simulated, conditions=CONDITIONS,
                               iso_poses=POSES, acceptance=Acceptance(20.0, max_ap, max_rp), traceability=TRACE,
                               config_toml='[body]\npoints = [{ id = "C1.0000000001", pose = [-170.00000000000003, '
                                           '-3.552713678800501e-15, 40.0, 0.0, 0.0, 10.0] }]\n')


def render(tmp_path: Path, d: ReportData) -> tuple[Page, str, str]:
    html = write_report(tmp_path, d).read_text(encoding="utf-8")
    return Page(html), html, (tmp_path / "report.md").read_text(encoding="utf-8")


def test_acceptance_judges_ap_and_rp_per_pose_beside_the_gain(tmp_path):
    page, _, md = render(tmp_path, signoff_data())
    acc = {r[0]: r[1:] for r in page.tables["acceptance-table"][1:]}
    gain = acc["improvement ratio (RMS before / RMS after), the outcome's target"]
    assert gain == ["≥ 20 ×", "34.4 ×", "PASS"]
    ap = acc["AP after correction, every pose (ISO 9283)"]
    assert ap[0] == "≤ 10 µm" and ap[1].startswith("largest 12.5 µm at C1.d elbow +1; 2 of 3") and ap[2] == "FAIL"
    rp = acc["RP after correction, every pose (ISO 9283)"]
    assert rp[1].startswith("largest 41.0 µm at C2.b elbow -1; 2 of 3") and rp[2] == "FAIL"
    # the verdict says what was judged (issue 29)
    assert page.texts["verdict"] == "FAIL (AP, RP); passed: gain" and "### Acceptance: FAIL (AP, RP); passed: gain" in md
    # per pose: the figures, and which limit a pose fails
    iso = page.tables["iso-table"]
    assert iso[0] == list(so.ISO_HEAD)
    assert iso[1] == ["C1.b", "-1", "3 / 3", "462.7", "10.9", "3.5", "14.4", "PASS"]
    assert iso[2][-1] == "FAIL (AP)" and iso[3][-1] == "FAIL (RP)"
    assert iso[-1][:1] == ["largest"] and iso[-1][3:7] == ["892.4", "31.8", "12.5", "41.0"]
    assert "fail" in page.cell_classes["iso-table"][2][-1]


def test_without_a_specification_only_the_gain_is_judged(tmp_path):
    page, _, _ = render(tmp_path, signoff_data(max_ap=None, max_rp=None))
    acc = page.tables["acceptance-table"][1:]
    assert [r[3] for r in acc] == ["PASS", "not judged", "not judged"]
    assert "not specified ([verification] max_ap_um)" in acc[1][1]
    assert page.texts["verdict"] == "PASS (gain); AP, RP not judged: no limit set"
    assert all(r[-1] in ("—", "") for r in page.tables["iso-table"][1:])


def test_without_after_measurements_the_limits_are_not_judged(tmp_path):
    d = dataclasses.replace(signoff_data(), errors_after_um=[], oracle_after_um=None,
                            summary=make_data(after=False).summary)
    page, _, _ = render(tmp_path, d)
    acc = page.tables["acceptance-table"][1:]
    assert [r[3] for r in acc] == ["not judged"] * 3
    assert acc[1][2] == "no measurements after correction"
    assert page.texts["verdict"].startswith("not judged: gain, AP, RP: ")


def test_conditions_poses_and_traceability(tmp_path):
    page, html, md = render(tmp_path, signoff_data())
    cond = dict(page.tables["conditions-table"])
    assert cond["identification"].startswith("30 poses (point and elbow), 4 visits each: 120 measurements")
    assert cond["verification"].startswith("3 held-out poses, 3 ISO 9283 cycles each")
    assert cond["speed"] == "50 % of the robot's maximum"
    assert cond["load on the flange"] == "the probe head 'seven'; 1.8 kg"
    assert cond["air temperature"].startswith("21.4 °C")
    assert cond["warm-up"].startswith("none configured")
    poses = page.tables["poses-table"]
    assert poses[0] == list(so.POSES_HEAD)
    assert poses[2] == ["C1.d", "+1", "-23.169", "0.000", "100.000", "3", "3"]  # never "-0.000"
    tr = dict(page.tables["traceability-table"])
    assert tr["robot serial number"] == "S600-0042" and tr["controller"] == "RC-600 s/n 7781"
    assert tr["operator"] == "A. Operator (--operator)"
    assert tr["probe head"] == "'seven', file head.toml: certificate CMM-H-17, measured 2026-10-28"
    assert tr["calibration body"] == "20 measuring points, file body.csv: certificate CMM-B-42, date not given"
    assert tr["git commit"] == "0123456789ab"
    # an empty signature block, the last section
    sig = page.tables["signature-table"]
    assert [r[0] for r in sig[1:]] == list(so.SIGNATURE_ROLES) and all(c == "" for r in sig[1:] for c in r[1:])
    assert page.sections[-1] == "signoff" and "## Sign-off" in md
    assert page.texts["signature-attests"] == so.SIGNATURE_ATTESTS and "rehearsal" not in page.texts


def test_not_recorded_items_say_where_to_give_them(tmp_path):
    d = dataclasses.replace(signoff_data(), traceability=Traceability(head="reference", body="24 measuring points"),
                            conditions=dataclasses.replace(CONDITIONS, load_kg=None, temperature_c=None))
    page, _, _ = render(tmp_path, d)
    tr = dict(page.tables["traceability-table"])
    assert "[cell] robot_serial" in tr["robot serial number"] and "[cell] controller" in tr["controller"]
    assert "--operator NAME" in tr["operator"]
    assert "built-in reference head" in tr["probe head"] and "inline" in tr["calibration body"]
    cond = dict(page.tables["conditions-table"])
    assert "[verification] load_kg" in cond["load on the flange"]
    assert "not recorded ([verification] temperature_c)" == cond["air temperature"]


def test_a_simulated_run_is_marked_on_every_page(tmp_path):
    page, html, md = render(tmp_path, signoff_data(simulated=True))
    assert page.texts["simulated-banner"] == so.SIMULATED_BANNER
    # every printed page: the mark in the running header (a page-margin box) and a fixed watermark
    assert '@top-right { content: "SIMULATED: rehearsal: not for sign-off"' in html and 'class="watermark"' in html
    assert "<title>SIMULATED — " in html
    assert md.startswith("# SIMULATED — ") and so.SIMULATED_BANNER in md
    # no signature block on a rehearsal: it is replaced, not qualified
    assert "signature-table" not in page.tables and page.texts["rehearsal"].startswith("Rehearsal: not for sign-off.")
    assert "Rehearsal: not for sign-off." in md and "| role |" not in md
    page, html, md = render(tmp_path / "real", signoff_data())
    assert "simulated-banner" not in page.texts and "SIMULATED" not in html and "SIMULATED" not in md


def test_numbers_and_timestamps_are_rounded(tmp_path):
    page, html, md = render(tmp_path, signoff_data())
    assert "702231" not in html and "702231" not in md
    assert dict(page.tables["record-table"])["created"] == "2026-12-01 23:57:22 UTC"
    assert "-170.00000000000003" not in html and "e-15" not in page.texts["config"]
    assert "pose = [-170.0, 0.0, 40.0" in page.texts["config"]
    assert 'id = "C1.0000000001"' in page.texts["config"]  # text in quotes is not a number
    assert "mm / µm" not in md and "° / ″" not in md
    assert timestamp_text("2026-04-01T09:30:12.5Z") == "2026-04-01 09:30:12 UTC"
    assert timestamp_text("yesterday") == "yesterday" and timestamp_text("") == "—"
    assert so.tidy_config("x = 1.25\n") == "x = 1.25\n" and not so.snapshot_changed("x = 1.25\n")


def test_software_rows_never_fail_without_git(tmp_path, monkeypatch):
    assert git_commit(tmp_path) is None  # not a checkout
    monkeypatch.setenv("PATH", str(tmp_path))  # no git on the PATH
    assert git_commit(ROOT) is None
    rows = dict(software_rows("0.0.9", ROOT))
    assert rows["station version of the run"] == "0.0.9" and rows["git commit"].startswith("not known")
    assert rows["numpy"][0].isdigit() and rows["scipy"][0].isdigit() and rows["Python"][0].isdigit()


def test_operator_names_are_checked():
    assert check_operator("  J. Smith ") == "J. Smith"
    for bad in ("", "  ", "a\nb", "x" * 257):
        with pytest.raises(ConfigError, match="--operator"):
            check_operator(bad)


# ----------------------------------------------------------------------------- the files' fields
def test_verification_and_cell_fields_in_the_configuration():
    text = TEMPLATE.replace('name = "cell 1"\n', 'name = "cell 1"\nrobot_serial = "S1"\ncontroller = "C1"\n'
                                                 'operator = "Jo"\n')
    text = text.replace("[verification]\n", "[verification]\nmax_ap_um = 40.0\nmax_rp_um = 25.0\n"
                                            "temperature_c = 21.5\nload_kg = 2.0\n")
    cfg = parse_text(text)
    assert (cfg.identity.robot_serial, cfg.identity.controller, cfg.identity.operator) == ("S1", "C1", "Jo")
    v = cfg.verification
    assert (v.max_ap_um, v.max_rp_um, v.temperature_c, v.load_kg) == (40.0, 25.0, 21.5, 2.0)
    assert parse_text(TEMPLATE).verification.max_ap_um is None
    for bad, where in (("max_ap_um = 0.0", "verification.max_ap_um"), ("temperature_c = 200.0", "verification.temperature_c"),
                       ('max_rp_um = "5"', "verification.max_rp_um")):
        with pytest.raises(ConfigError, match=where):
            parse_text(TEMPLATE.replace("[verification]\n", f"[verification]\n{bad}\n"))
    with pytest.raises(ConfigError, match="cell.operator"):
        parse_text(TEMPLATE.replace('name = "cell 1"\n', 'name = "cell 1"\noperator = ""\n'))


def test_template_lists_simulation_with_every_key_and_its_bounds():
    block = TEMPLATE[TEMPLATE.index("\n[simulation]\n"):]
    for key in _Simulation.model_fields:
        assert f"\n# {key} = " in block, key
    assert "# repeatability_um = 5.0" in block and "0 … 1000" in block
    assert "# seed = 1 " in block and "0 … 4294967295" in block
    # uncommented, the keys that show a value (a per-joint list shows its form) read as the schema's
    settings = [line[2:].split("#")[0] for line in block.splitlines() if line.startswith("# ") and " = " in line
                and line[2:].split(" = ")[0] in _Simulation.model_fields and "[ … ]" not in line]
    data = tomllib.loads("\n".join(settings))
    assert len(data) >= len(_Simulation.model_fields) - 3 and "repeatability_um" in data
    assert _Simulation.model_validate(data).repeatability_um == 5.0


def test_head_certificate_fields():
    text = (ROOT / "examples/heads/reference-321.toml").read_text(encoding="utf-8")
    with_cert = text.replace("[head]\n", '[head]\ncertificate_id = "CMM-H-1"\ncertificate_date = 2026-11-02\n', 1)
    assert parse_head(tomllib.loads(with_cert)).certificate == so_cert("CMM-H-1", "2026-11-02")
    as_text = text.replace("[head]\n", '[head]\ncertificate_date = "2026-11-02"\n', 1)
    assert parse_head(tomllib.loads(as_text)).certificate.date == "2026-11-02"
    assert not parse_head(tomllib.loads(text)).certificate
    for bad in ('certificate_date = "2026-13-02"', "certificate_date = 5", 'certificate_id = ""'):
        with pytest.raises(ConfigError, match=r"head\.certificate_"):
            parse_head(tomllib.loads(text.replace("[head]\n", f"[head]\n{bad}\n", 1)))


def so_cert(cid: str, date: str):
    from station.io.certificate import Certificate

    return Certificate(cid, date)


def test_body_certificate_comment_lines(tmp_path):
    body = (ROOT / "examples/bodies/reference-body.csv").read_text(encoding="utf-8")
    p = tmp_path / "body.csv"
    p.write_text("# certificate_id: CMM-B-0142\n# certificate_date = 2026-11-02\n" + body, encoding="utf-8")
    assert read_body_file(p).certificate == so_cert("CMM-B-0142", "2026-11-02")
    p.write_text(body, encoding="utf-8")
    assert not read_body_file(p).certificate
    p.write_text("# certificate_date: 2026-02-30\n" + body, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"line 1: certificate_date: .*YYYY-MM-DD"):
        read_body_file(p)
    p.write_text("# certificate_id: A\n# certificate_id: B\n" + body, encoding="utf-8")
    with pytest.raises(ConfigError, match="line 2: certificate_id was already given on line 1"):
        read_body_file(p)


def test_the_certificates_reach_the_configuration(tmp_path):
    example = ROOT / "examples/scara600"
    for name in ("robot.toml", "cell.toml"):
        (tmp_path / name).write_text((example / name).read_text(encoding="utf-8"), encoding="utf-8")
    (tmp_path / "head.toml").write_text((example / "head.toml").read_text(encoding="utf-8").replace(
        "[head]\n", '[head]\ncertificate_id = "H-7"\n', 1), encoding="utf-8")
    (tmp_path / "body.csv").write_text("# certificate_id: B-9\n# certificate_date: 2026-11-02\n"
                                       + (example / "body.csv").read_text(encoding="utf-8"), encoding="utf-8")
    cfg = parse_text((tmp_path / "cell.toml").read_text(encoding="utf-8"), str(tmp_path / "cell.toml"))
    assert cfg.head_certificate == so_cert("H-7", "") and cfg.body_certificate == so_cert("B-9", "2026-11-02")
