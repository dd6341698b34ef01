"""The conformance units the station's server claims (OPC 10000-7: Method Call, Base Info Server
Capabilities / BuildInfo; OPC 40001-1 Machinery "Find Machines"; OPC 40001-101 Result
Management) and the hardening of issue 39, against the real server process (``station serve
--opcua … --simulated``) with asyncua's client; the guards themselves in this process."""

from __future__ import annotations

import asyncio
import logging
from importlib import metadata

import pytest
from asyncua import ua
from asyncua.ua.uaerrors import BadArgumentsMissing, BadInvalidArgument, BadMethodInvalid, BadTooManyArguments

from station.cell.config.cell_config import load_config
from station.cell.records.rundb import RunDB
from station.ui.cli.main import main
from station.ui.opcua.guard import MAX_STRING, BoundedLog, Signature, check_call
from station.ui.opcua.model import OffsetParameter, identified_offsets
from station.ui.opcua.security import LOCKOUT_S, MAX_FAILURES, StationUserManager, add_user, read_users
from station.ui.opcua.server import ServeOptions, build_server, offset_parameters
from tests.opcua.clients import CONFIG, PASSWORDS, Collector, connected, read, station, subscribe_station

RESULT_NS = "http://opcfoundation.org/UA/Machinery/Result/"
MACHINERY_NS = "http://opcfoundation.org/UA/Machinery/"


# --- against the server process ------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.timeout(300)
async def test_build_info_and_machines_say_what_the_station_is(served, pki) -> None:
    async with connected(served.url, pki.client_cert, pki.client_key, user="watch", password=PASSWORDS["watch"]) as c:
        info = await c.get_node(ua.ObjectIds.Server_ServerStatus_BuildInfo).read_value()
        assert info.ProductName == "calibration-station"  # not "FreeOpcUa Python Server"
        assert info.SoftwareVersion == metadata.version("calibration-station")
        assert info.ProductUri == "urn:robot-calibration-station" and info.BuildNumber
        assert "FreeOpcUa" not in info.ManufacturerName
        machinery = await c.get_namespace_index(MACHINERY_NS)
        machines = await c.nodes.objects.get_child([f"{machinery}:Machines"])
        idx = await c.get_namespace_index("urn:robot-calibration-station:opcua:station")
        found = {(await n.read_browse_name()).Name
                 for n in await machines.get_children(refs=ua.ObjectIds.Organizes)}
        assert found == {"Robot", "CalibrationStation"}  # OPC 40001-1 §9.2: every machine, directly
        assert ua.NodeId("Robot", idx) in {n.nodeid for n in await machines.get_children()}


@pytest.mark.slow
@pytest.mark.timeout(300)
async def test_calls_are_checked_before_they_run(served, pki) -> None:
    size_before = served.log.stat().st_size
    async with connected(served.url, pki.client_cert, pki.client_key, user="line", password=PASSWORDS["line"]) as c:
        idx, node = await station(c)
        rns = await c.get_namespace_index(RESULT_NS)
        results = await node.get_child([f"{rns}:ResultManagement"])
        start_recheck = await node.get_child([f"{idx}:StartRecheck"])
        # a station method called on the ResultManagement object: not its method, nothing starts
        with pytest.raises(BadMethodInvalid):
            await results.call_method(start_recheck)
        assert await read(node, idx, "State") == "Idle" and await read(node, idx, "RunId") == 0
        with pytest.raises(BadTooManyArguments):  # was BadUnexpectedError
            await results.call_method(f"{rns}:GetResultById", ua.Variant("run-1"), ua.Variant(1, ua.VariantType.Int32),
                                      ua.Variant(2, ua.VariantType.Int32))
        with pytest.raises(BadTooManyArguments):
            await node.call_method(f"{idx}:Acknowledge", ua.Variant(1, ua.VariantType.Int32))
        with pytest.raises(BadArgumentsMissing):
            await results.call_method(f"{rns}:GetResultById", ua.Variant("run-1"))
        with pytest.raises(BadInvalidArgument):  # ResultId must be a String, Timeout an Int32
            await results.call_method(f"{rns}:GetResultById", ua.Variant(7, ua.VariantType.Int64),
                                      ua.Variant(1, ua.VariantType.Int32))
        with pytest.raises(BadInvalidArgument):
            await results.call_method(f"{rns}:GetLatestResult", ua.Variant("soon"))
        for _ in range(3):  # the 3 calls of 3 MB that wrote 9.2 MB of log
            with pytest.raises(BadInvalidArgument):
                await results.call_method(f"{rns}:GetResultById", ua.Variant("x" * 3_000_000),
                                          ua.Variant(1, ua.VariantType.Int32))
        assert await read(node, idx, "State") == "Idle"
    assert served.log.stat().st_size - size_before < 20_000
    assert served.process.poll() is None


@pytest.mark.slow
@pytest.mark.timeout(300)
async def test_offsets_read_nan_where_not_identified_and_message_shows_the_abort(served, pki) -> None:
    async with connected(served.url, pki.client_cert, pki.client_key, user="line", password=PASSWORDS["line"]) as c:
        idx, node = await station(c)
        handler = Collector()
        await subscribe_station(c, idx, node, handler, "State")
        await node.call_method(f"{idx}:StartCalibration")
        calibrated = await asyncio.wait_for(handler.events.get(), 240)
        assert calibrated.Verdict == "SUCCESS"
        rob = await c.get_namespace_index("http://opcfoundation.org/UA/Robotics/")
        axes = await c.nodes.objects.get_child([f"{idx}:Robot", f"{rob}:MotionDevices", f"{rob}:scara600", f"{rob}:Axes"])
        offsets = [await (await axes.get_child([f"{rob}:Axis{j}", f"{idx}:IdentifiedOffset"])).read_value()
                   for j in (1, 2, 3, 4)]
        with RunDB(str(served.db)) as db:
            chosen = set(db.load_result(calibrated.RunId, "identification")["chosen"])
        specs = offset_parameters(load_config(str(CONFIG)))
        identified = [s is not None and s.name in chosen for s in specs]
        assert any(identified) and not all(identified)  # scara600: a joint offset merges into another parameter
        for value, known in zip(offsets, identified):  # NaN exactly where not identified (it read 0.0)
            assert (value == value) == known, (offsets, identified)
        await node.call_method(f"{idx}:Acknowledge")
        await node.call_method(f"{idx}:StartRecheck")
        await node.call_method(f"{idx}:Abort")
        aborted = await asyncio.wait_for(handler.events.get(), 120)
        assert aborted.Verdict == "ABORTED"
        message = await read(node, idx, "Message")
        assert message.startswith(f"recheck run {aborted.RunId}: ABORTED (exit code 6)"), message
        await node.call_method(f"{idx}:Acknowledge")


# --- in this process ------------------------------------------------------------------------------------
def test_check_call_answers_with_the_standard_codes() -> None:
    here, there = ua.NodeId("CalibrationStation", 7), ua.NodeId("CalibrationStation.Results", 7)
    sig = Signature(frozenset({there}), (ua.VariantType.String, ua.VariantType.Int32))
    ok = (ua.Variant("run-3"), ua.Variant(5, ua.VariantType.Int32))
    assert check_call(sig, there, ok) is None
    assert check_call(sig, here, ok).StatusCode.value == ua.StatusCodes.BadMethodInvalid
    long = check_call(sig, there, (ua.Variant("x" * (MAX_STRING + 1)), ok[1]))
    assert long.StatusCode.value == ua.StatusCodes.BadInvalidArgument
    assert [r.value for r in long.InputArgumentResults] == [ua.StatusCodes.BadOutOfRange, ua.StatusCodes.Good]
    typed = check_call(sig, there, (ok[0], ua.Variant(5.0, ua.VariantType.Double)))
    assert [r.value for r in typed.InputArgumentResults] == [ua.StatusCodes.Good, ua.StatusCodes.BadTypeMismatch]
    array = check_call(sig, there, (ua.Variant(["a", "b"]), ok[1]))
    assert array.InputArgumentResults[0].value == ua.StatusCodes.BadTypeMismatch


def test_the_log_is_bounded_in_size_and_rate() -> None:
    now = [0.0]
    filt = BoundedLog(max_chars=1000, per_minute=5, clock=lambda: now[0])
    logger = logging.getLogger("asyncua.test-bounded")
    records: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(self.format(record))

    handler = Keep()
    handler.addFilter(filt)
    logger.addHandler(handler)
    logger.propagate = False
    try:
        try:
            raise TypeError("y" * 50_000)
        except TypeError:
            logger.exception("Error executing method call %s", "x" * 3_000_000)
        assert len(records) == 1 and len(records[0]) < 1200 and "characters left out" in records[0]
        for _ in range(20):
            logger.warning("again")
        assert len(records) == 5  # 5 a minute
        now[0] = 61.0
        logger.warning("later")
        assert len(records) == 6 and "16 earlier records" in records[-1]
    finally:
        logger.removeHandler(handler)


def test_identified_offset_is_nan_for_a_joint_not_identified() -> None:
    specs = [OffsetParameter(3, "A1.yaw", 0.0, 57.29577951308232), OffsetParameter(9, "A2.yaw", 0.5, 57.29577951308232),
             OffsetParameter(15, "A3.z", 10.0, 1.0), None]
    params = [0.0] * 20
    params[3], params[9], params[15] = 0.001, 0.5, 10.02  # A2.yaw not chosen: the vector holds its nominal
    values = identified_offsets({"params": params, "chosen": ["A1.yaw", "A3.z"]}, specs)
    assert values[0] == pytest.approx(0.0572958, rel=1e-5) and values[2] == pytest.approx(0.02)
    assert values[1] != values[1] and values[3] != values[3]  # NaN, not the 0.0 read before
    assert all(v != v for v in identified_offsets(None, specs))


def test_wrong_passwords_lock_the_name_out_for_a_while(tmp_path) -> None:
    users = tmp_path / "users.toml"
    add_user(users, "mes", "operator", "right-one")
    now = [100.0]
    manager = StationUserManager(read_users(users), clock=lambda: now[0])
    for _ in range(MAX_FAILURES):
        assert manager.get_user(None, username="mes", password="guess") is None
    assert manager.get_user(None, username="mes", password="right-one") is None  # locked: even the right one
    now[0] += LOCKOUT_S
    assert manager.get_user(None, username="mes", password="right-one") is not None


async def test_a_fresh_pki_with_an_empty_trust_list_serves(tmp_path) -> None:
    """docs/opcua.md's steps 1, 3, 4 as written: the trust list is empty until a client is added."""
    assert main(["serve", "--init-pki", str(tmp_path / "pki"), "--host", "localhost"]) == 0
    assert not any((tmp_path / "pki" / "trusted").iterdir())
    add_user(tmp_path / "users.toml", "mes", "operator", "pw")
    server, _, _ = await build_server(ServeOptions(config=str(CONFIG), users=str(tmp_path / "users.toml"),
                                                   pki=str(tmp_path / "pki"), simulated=True,
                                                   db=str(tmp_path / "runs.sqlite")))
    from cryptography import x509

    own = x509.load_der_x509_certificate((tmp_path / "pki" / "own" / "cert.der").read_bytes())
    validator = server.iserver.certificate_validator
    assert validator is not None
    assert not validator._trust_store.validate(own)  # type: ignore[attr-defined]  # an empty list trusts no client
