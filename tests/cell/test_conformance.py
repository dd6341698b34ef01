"""station conformance against the simulated controller (register map 3), and against deliberately
wrong variants of it (``SimulatedController(quirks=...)``): the simulator passes every requirement,
at register base 0 and in a 128-register window at 128; each wrong variant fails exactly its
requirement. Also: the kit moves only inside the park zone, leaves the controller's three table
slots as it found them (or, when it cannot read a table back, touches none), and
docs/robot-program.md lists every register of the map."""

from __future__ import annotations

import json
import re
import socket
from pathlib import Path

import numpy as np
import pytest

from drivers.controller import ModbusController
from drivers.controller_errors import ControllerClaimed
from drivers.controller_map import REGISTERS, Command, ErrorCode, StatusBit, WordOrder
from simulators.controller_server import QUIRKS, SimulatedController
from station.cell.config.cell_config import parse_text
from station.cell.conformance import suite as cf
from station.core.table.values import CorrectionTableData, TableAxis
from station.errors import ConfigError
from station.ui.cli.main import main

DOC = Path(__file__).resolve().parents[2] / "docs" / "robot-program.md"
PARK = "[0.0, 0.0, -1.0, 0.0]"  # joint 3 (the quill) 1 mm below its upper limit 0 mm: inside the 2 mm zone


def config_text(port: int, order: str = "big", park: str | None = PARK, base: int = 0) -> str:
    conformance = "" if park is None else f"[conformance]\npark_joints = {park}\ntest_move = 2.0\n"
    return f"""
[robot]
model = "sr800"
[body]
points = [
  {{ id = "a", pose = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0] }},
  {{ id = "b", pose = [10.0, 0.0, 0.0, 0.0, 0.0, 0.0] }},
  {{ id = "c", pose = [0.0, 10.0, 0.0, 0.0, 0.0, 0.0] }},
]
[devices]
controller = "127.0.0.1:{port}"
word_order = "{order}"
controller_register_base = {base}
{conformance}"""


@pytest.fixture
def sent_targets(monkeypatch):
    """Every command block the kit writes: (code, seq, joints)."""
    sent: list[tuple[int, int, np.ndarray | None]] = []
    original = cf._Link.send_block

    def record(self, code, seq, joints=None, speed=0.0, token=None):
        sent.append((int(code), int(seq), None if joints is None else np.array(joints, dtype=float)))
        return original(self, code, seq, joints, speed, token)

    monkeypatch.setattr(cf._Link, "send_block", record)
    return sent


@pytest.mark.parametrize("order,base", [(WordOrder.BIG, 0), (WordOrder.LITTLE, 0), (WordOrder.BIG, 128)])
def test_the_simulator_passes_every_requirement_inside_the_park_zone(order, base, sent_targets):
    with SimulatedController(time_scale=1.0, word_order=order, register_base=base, register_count=128) as sim:
        q_start = sim.joints
        cfg = parse_text(config_text(sim.port, order.value, base=base))
        report = cf.run_conformance(cfg)
        assert report.passed, "\n".join(report.describe())
        assert [r.id for r in report.requirements] == [rid for rid, _ in cf.REQUIREMENTS]
        np.testing.assert_allclose(sim.joints, q_start, atol=1e-9)  # back where it was parked
        assert sim.active_table is None  # no table was active, none is
        assert all(c == 0 for c in (sim.register("table_staged_crc"), sim.register("table_previous_crc")))
        # every request of the kit lay in the window (the simulator refuses any other with exception 2)
        assert all(base <= a and a + n <= base + 128 for _fc, a, n in sim.requests_log)
        assert {fc for fc, _a, _n in sim.requests_log} <= {3, 16}
    assert cfg.conformance is not None
    zone = cfg.conformance.zone()
    motions = [q for code, _, q in sent_targets if code == Command.MOVE_JOINTS]
    assert len(motions) >= 5
    for q in motions:  # never a target outside the park zone (the soft-limit probe included)
        assert q is not None and np.all(q[:4] >= zone[:, 0] - 1e-9) and np.all(q[:4] <= zone[:, 1] + 1e-9), q
    assert report.to_json()["exit_code"] == 0


@pytest.mark.parametrize("quirk,requirement", [
    ("swapped_word_order", "word_order"),
    ("ack_without_seq", "ack"),
    ("no_heartbeat", "heartbeat"),
    ("ack_after_answer", "ack"),
    ("crc_mismatch", "table"),
    ("done_before_motion", "done"),
    ("page_crc_ignored", "pages"),
    ("no_slot_reads", "slot_reads"),
    ("activate_drops_previous", "keep_previous"),
    ("claim_always_granted", "claim"),
    ("claim_never_expires", "claim"),
])
def test_each_wrong_variant_fails_exactly_its_requirement(quirk, requirement):
    assert quirk in QUIRKS
    with SimulatedController(time_scale=1.0, quirks={quirk}) as sim:
        report = cf.run_conformance(parse_text(config_text(sim.port)))
        crcs = {k: sim.register(f"table_{k}_crc") for k in ("staged", "active", "previous")}
    failed = {r.id for r in report.requirements if r.status == cf.FAILED}
    assert failed == {requirement}, "\n".join(report.describe())
    assert report.requirement(requirement).fix  # it says what to fix
    for other in report.requirements:  # what could not be checked after it says why
        assert other.status != cf.NOT_CHECKED or any(d.startswith("not checked: ") for d in other.detail), other
    assert report.outcome == 7
    assert report.requirement("slots_restored").status == cf.PASSED
    assert crcs == {"staged": 0, "active": 0, "previous": 0}  # the slots were empty: they are again


def _tables() -> dict[str, CorrectionTableData]:
    """The operator's tables: P (previous), A (active) and S (staged), each a different CRC-32."""
    return {slot: CorrectionTableData((TableAxis(250.0, 100.0, n),), np.full((1, n, 4), value))
            for slot, n, value in (("previous", 2, 3e-5), ("active", 2, 1e-5), ("staged", 3, 2e-5))}


def _load_slots(port: int, base: int = 0) -> dict[str, int]:
    """P previous, A active, S staged, as the station's own runs leave them; the slot CRCs."""
    t = _tables()
    with ModbusController("127.0.0.1", port, heartbeat_period=None, register_base=base) as c:
        for slot in ("previous", "active", "staged"):
            c.upload_table(t[slot])
            c.verify_table()
            c.stage_table()
            if slot != "staged":
                c.activate_table()
        crcs = c.table_crcs()
    assert crcs == {k: t[k].crc32() for k in crcs}
    return crcs


def _slot_tables(port: int, base: int = 0) -> dict[str, CorrectionTableData | None]:
    with ModbusController("127.0.0.1", port, heartbeat_period=None, register_base=base) as c:
        return {slot: c.read_slot_table(slot) for slot in ("staged", "active", "previous")}


@pytest.mark.parametrize("base", [0, 128])
def test_the_three_table_slots_are_left_as_found(base):
    with SimulatedController(time_scale=0.0, register_base=base, register_count=128) as sim:
        before = _load_slots(sim.port, base)
        report = cf.run_conformance(parse_text(config_text(sim.port, base=base)))
        assert report.passed, "\n".join(report.describe())
        after = _slot_tables(sim.port, base)
        # a later roll back revives the operator's P, not a test table of the kit
        with ModbusController("127.0.0.1", sim.port, heartbeat_period=None, register_base=base) as c:
            c.rollback_table()
            rolled = c.table_crcs()
    for slot, table in _tables().items():
        got = after[slot]
        assert got is not None and got.same_as(table) and got.crc32() == before[slot], slot
    assert "slots as found" in " ".join(report.requirement("slots_restored").detail)
    assert rolled["active"] == before["previous"] and rolled["previous"] == before["active"]


@pytest.mark.parametrize("quirk", ["activate_drops_previous", "page_crc_ignored", "crc_mismatch", "no_heartbeat"])
def test_a_faulty_program_gets_its_table_slots_back_too(quirk):
    with SimulatedController(time_scale=0.0, quirks={quirk}) as sim:
        before = _load_slots(sim.port) if quirk != "crc_mismatch" else None
        report = cf.run_conformance(parse_text(config_text(sim.port)))
        after = {k: sim.register(f"table_{k}_crc") for k in ("staged", "active", "previous")}
    assert not report.passed
    assert after == (before or {"staged": 0, "active": 0, "previous": 0}), "\n".join(report.describe())
    assert report.requirement("slots_restored").status == cf.PASSED


def test_a_program_without_slot_reads_keeps_its_tables_untouched():
    """The kit cannot read the tables back, so it cannot put them back: it changes no slot."""
    with SimulatedController(time_scale=0.0, quirks={"no_slot_reads"}) as sim:
        before = _load_slots(sim.port)
        n_writes = len(sim.command_writes)
        report = cf.run_conformance(parse_text(config_text(sim.port)))
        with ModbusController("127.0.0.1", sim.port, heartbeat_period=None) as c:
            after = c.table_crcs()
        kit_codes = {code for code, _seq in sim.command_writes[n_writes:]}
    assert after == before
    assert not kit_codes & {int(c) for c in (Command.TABLE_STAGE, Command.TABLE_ACTIVATE, Command.TABLE_DEACTIVATE,
                                             Command.TABLE_ROLLBACK, Command.TABLE_DISCARD_PREVIOUS)}
    assert report.requirement("slot_reads").status == cf.FAILED
    for rid in ("activation", "discard_previous", "keep_previous"):
        r = report.requirement(rid)
        assert r.status == cf.NOT_CHECKED and "never destroys a table it could not put back" in " ".join(r.detail)
    assert report.requirement("table").status == cf.NOT_CHECKED  # written and read back, not staged
    assert report.requirement("slots_restored").status == cf.PASSED
    assert report.requirement("pages").status == cf.PASSED  # the transfer buffer was still checked


def test_slots_that_are_not_put_back_fail_loudly(monkeypatch):
    monkeypatch.setattr(cf._Kit, "_rebuild", lambda self: None)  # as a program whose slot rules defeat it
    with SimulatedController(time_scale=0.0) as sim:
        before = _load_slots(sim.port)
        report = cf.run_conformance(parse_text(config_text(sim.port)))
    r = report.requirement("slots_restored")
    assert r.status == cf.FAILED and "put the controller's tables back by hand" in " ".join(r.fix)
    assert f"active {before['active']:#010x}" in " ".join(r.detail)  # what it found, to put back
    assert any("TABLE SLOTS ARE NOT AS THE KIT FOUND THEM" in n for n in report.notes)
    assert not report.passed and report.outcome == 7


def test_a_robot_outside_the_park_zone_is_not_moved(sent_targets):
    with SimulatedController(time_scale=0.0) as sim:
        q_start = sim.joints
        report = cf.run_conformance(parse_text(config_text(sim.port, park="[30.0, 0.0, -1.0, 0.0]")))
        np.testing.assert_array_equal(sim.joints, q_start)
    for rid in ("sequence", "done", "soft_limit"):
        r = report.requirement(rid)
        assert r.status == cf.NOT_CHECKED and "jog it to [conformance].park_joints" in " ".join(r.detail + r.fix)
    assert not [code for code, _, _ in sent_targets if code in (Command.MOVE_JOINTS, Command.MOVE_CARTESIAN)]
    assert not report.passed and report.outcome == 7


def test_without_a_limit_in_the_park_zone_the_soft_limit_check_is_not_run():
    with SimulatedController(time_scale=0.0) as sim:
        with ModbusController("127.0.0.1", sim.port, heartbeat_period=None) as c:
            c.move_joints([0.0, 0.0, -50.0, 0.0]).wait(2.0)  # the operator parks the robot
        report = cf.run_conformance(parse_text(config_text(sim.port, park="[0.0, 0.0, -50.0, 0.0]")))
    r = report.requirement("soft_limit")
    assert r.status == cf.NOT_CHECKED and "within test_move of its soft limit" in " ".join(r.fix)
    assert {x.id for x in report.requirements if x.status != cf.PASSED} == {"soft_limit"}


def test_configuration_of_the_park_zone():
    text = config_text(1502)
    assert parse_text(config_text(1502, park=None)).conformance is None
    with pytest.raises(ConfigError, match="conformance.park_joints is missing"):
        cf.run_conformance(parse_text(config_text(1502, park=None)))
    with pytest.raises(ConfigError, match="park_joints lists 3 joints"):
        parse_text(config_text(1502, park="[0.0, 0.0, -1.0]"))
    with pytest.raises(ConfigError, match="joint 3 = 5 mm is outside the soft limits"):
        parse_text(config_text(1502, park="[0.0, 0.0, 5.0, 0.0]"))
    with pytest.raises(ConfigError, match=re.escape("conformance.test_move")):
        parse_text(text.replace("test_move = 2.0", "test_move = 50.0"))
    c = parse_text(text).conformance
    assert c is not None
    np.testing.assert_allclose(c.zone()[2], [-3.0, 1.0])
    np.testing.assert_allclose(c.zone()[0], np.radians([-2.0, 2.0]))


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_cli(tmp_path, capsys):
    with SimulatedController(time_scale=0.0) as sim:
        p = tmp_path / "cell.toml"
        p.write_text(config_text(sim.port))
        assert main(["conformance", str(p), "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        assert out["passed"] and out["outcome"] == "SUCCESS" and len(out["requirements"]) == len(cf.REQUIREMENTS)
        assert main(["conformance", str(p)]) == 0
        assert f"{len(cf.REQUIREMENTS)} of {len(cf.REQUIREMENTS)} requirements passed" in capsys.readouterr().out
    p.write_text(config_text(_closed_port()))
    assert main(["conformance", str(p), "--json"]) == 7
    captured = capsys.readouterr()
    assert json.loads(captured.out)["exit_code"] == 7 and "Traceback" not in captured.err
    p.write_text(config_text(1502, park=None))
    assert main(["conformance", str(p), "--json"]) == 2
    assert json.loads(capsys.readouterr().out)["exit_code"] == 2


# ------------------------------------------------------------------ the robot programmer's document

def register_rows() -> list[str]:
    """The register table of docs/robot-program.md, generated from the map (the one source)."""
    rows = []
    for r in REGISTERS:
        where = f"{r.address}" if r.n_registers == 1 else f"{r.address}–{r.end - 1}"
        count = f"{r.type.value}" if r.count == 1 else f"{r.type.value} × {r.count}"
        writer = "PC" if r.access == "rw" else "robot program"
        rows.append(f"| {where} | `{r.name}` | {count} | {writer} | {r.unit} | {r.meaning} |")
    return rows


def test_robot_program_document_lists_every_register_and_code():
    doc = DOC.read_text(encoding="utf-8")
    for row in register_rows():
        assert row in doc, f"register row missing or out of date in {DOC.name}:\n{row}"
    for code in ErrorCode:
        assert f"| {int(code)} | `{code.name}` |" in doc, code
    for cmd in Command:
        assert f"| {int(cmd)} | `{cmd.name}` |" in doc, cmd
    for bit in StatusBit:
        assert f"`{bit.name}`" in doc, bit
    for rid, _ in cf.REQUIREMENTS:
        assert f"`{rid}`" in doc, rid
    assert "station conformance" in doc


def test_a_six_axis_cell_needs_no_table_on_its_controller():
    """An articulated arm gets compensated targets and no table (robot-programs/ur holds none): the
    table requirements are not applicable, with the reason, and every other one passes: exit 0
    (issue 28)."""
    from simulators.six_axis_cell import six_axis_config_text, start_six_axis_cell

    with start_six_axis_cell(seed=1) as srv:
        park = ", ".join(repr(float(v)) for v in np.degrees(srv.controller_server.joints))
        text = six_axis_config_text(srv, 1) + f"\n[conformance]\npark_joints = [{park}]\ntest_move = 2.0\n"
        report = cf.run_conformance(parse_text(text))
        assert srv.controller_server.active_table is None  # the kit sent no table
    by_id = {r.id: r for r in report.requirements}
    for rid in cf._TABLE_REQUIREMENTS:
        assert by_id[rid].status == cf.NOT_APPLICABLE and "compensated targets" in " ".join(by_id[rid].detail)
    # the handshake is checked as on a SCARA (the soft-limit refusal needs a joint parked at a limit)
    assert not [r for r in report.requirements if r.status == cf.FAILED], "\n".join(report.describe())
    for rid in ("identification", "word_order", "heartbeat", "ack", "done", "sequence", "error_codes"):
        assert by_id[rid].status == cf.PASSED, rid
    # the only requirement left is the soft-limit refusal (no joint parked at a limit): not checked
    assert by_id["soft_limit"].status == cf.NOT_CHECKED and report.outcome.value == 7
    assert "8 of 9 requirements passed (7 not applicable to this cell)" in "\n".join(report.describe())


def test_the_kits_own_safety_refusal_is_a_failed_requirement_not_an_abort(monkeypatch):
    """When the kit's motion guard refuses a target (the robot is not where the program was sent),
    the requirement being checked fails with the guard's words and what to fix, no further motion
    is commanded, and the exit code is the documented 7 - never 4 (issue 28)."""
    from station.cell.conformance import checks
    from station.errors import UnreachableError

    def refused(self):
        raise UnreachableError("conformance test move back (park zone): joint 2 = 0.4 is outside the soft limits "
                               "[0.5, 0.6]; the motion was not commanded")

    monkeypatch.setattr(checks._HandshakeChecks, "test_move", refused)
    with SimulatedController(time_scale=1.0) as sim:
        report = cf.run_conformance(parse_text(config_text(sim.port)))
    done, soft = report.requirement("done"), report.requirement("soft_limit")
    assert done.status == cf.FAILED and "joint 2 = 0.4" in " ".join(done.detail)
    assert any("park_joints" in f for f in done.fix)
    assert soft.status == cf.NOT_CHECKED and "no further motion" in " ".join(soft.detail)
    assert int(report.outcome) == 7


def test_the_kit_stops_at_a_controller_another_station_holds():
    """One station per controller: the kit is a station too. Against a controller another station
    holds it stops before its first transfer request and its first command, naming the holder."""
    with SimulatedController(time_scale=0.0) as sim:
        holder = ModbusController("127.0.0.1", sim.port, heartbeat_period=0.05).connect()
        try:
            xfer = sim.register("xfer_ack")
            with pytest.raises(ControllerClaimed, match=r"host 127\.0\.0\.1, PID \d+, since "):
                cf.run_conformance(parse_text(config_text(sim.port)))
            assert sim.register("xfer_ack") == xfer and sim.command_log == []  # nothing of the kit's went out
            assert sim.register("claim_owner") == holder.claim_token  # the holder keeps the controller
        finally:
            holder.close()


def test_an_answer_seen_before_its_acknowledgement_is_named_as_such():
    """The CI failure of the Epson program: one status read showed error_seq = n beside the old
    ack_seq. The kit names that pattern, and its fix (one read sees one state: a lock), rather
    than a missing acknowledgement."""
    with SimulatedController(time_scale=1.0, quirks={"ack_after_answer"}) as sim:
        report = cf.run_conformance(parse_text(config_text(sim.port)))
    ack = report.requirement("ack")
    assert ack.status == cf.FAILED
    assert any("one status read showed the answer but not the acknowledgement" in d for d in ack.detail), ack.detail
    assert any("lock" in f for f in ack.fix)
