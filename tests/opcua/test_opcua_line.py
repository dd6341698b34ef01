"""The line's sequence over OPC UA against ``station serve --opcua examples/scara600/cell.toml
--simulated`` (a real process, real simulated devices, a real client over SignAndEncrypt):
browse the model, calibrate (the recheck's baseline) while a subscriber follows the progress and
another one dies, refuse a second start, recheck, receive ResultReady with the verdict, read the
result, and read the state with asyncua's command-line ``uaread``."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from asyncua import ua
from asyncua.ua.uaerrors import BadInvalidState

from tests.opcua.clients import PASSWORDS, Collector, connected, read, station, subscribe_station

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]

#: a subscriber that dies mid-subscription: it subscribes, says so, and waits to be killed
DYING_CLIENT = """
import asyncio, sys
from asyncua import Client
async def main(url, cert, key, password):
    c = Client(url, timeout=20)
    await c.set_security_string(f"Basic256Sha256,SignAndEncrypt,{cert},{key}")
    c.set_user("watch"); c.set_password(password)
    await c.connect()
    idx = await c.get_namespace_index("urn:robot-calibration-station:opcua:station")
    node = await c.nodes.objects.get_child([f"{idx}:CalibrationStation", f"{idx}:Step"])
    class H:
        def datachange_notification(self, node, val, data):
            print("step", val, flush=True)
    sub = await c.create_subscription(10, H())
    await sub.subscribe_data_change(node)
    print("subscribed", flush=True)
    await asyncio.sleep(600)
asyncio.run(main(*sys.argv[1:]))
"""


async def _browse_names(node) -> set[str]:
    return {(await c.read_browse_name()).Name for c in await node.get_children()}


async def _until(node, idx: int, name: str, value: object) -> None:
    while await read(node, idx, name) != value:
        await asyncio.sleep(0.05)


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
async def test_line_sequence(served, pki, tmp_path: Path) -> None:
    async with connected(served.url, pki.client_cert, pki.client_key, user="line", password=PASSWORDS["line"]) as client:
        idx, node = await station(client)
        objects = client.nodes.objects
        await client.load_data_type_definitions()  # the Machinery Result structures, from the server's model

        # --- the model: the robot (OPC 40010), the body (OPC 10000-200), the station with its results
        robot = await objects.get_child([f"{idx}:Robot"])
        rob_ns = await client.get_namespace_index("http://opcfoundation.org/UA/Robotics/")
        assert await robot.read_type_definition() == ua.NodeId(1002, rob_ns)  # MotionDeviceSystemType
        device = await robot.get_child([f"{rob_ns}:MotionDevices", f"{rob_ns}:scara600"])
        di = await client.get_namespace_index("http://opcfoundation.org/UA/DI/")
        assert (await (await device.get_child([f"{di}:Model"])).read_value()).Text == "scara600"
        axes = await device.get_child([f"{rob_ns}:Axes"])
        assert await _browse_names(axes) == {"Axis1", "Axis2", "Axis3", "Axis4"}
        body = await objects.get_child([f"{idx}:CalibrationBody"])
        ia = await client.get_namespace_index("http://opcfoundation.org/UA/IA/")
        assert await body.read_type_definition() == ua.NodeId(1019, ia)  # CalibrationTargetType
        assert await (await body.get_child([f"{ia}:CertificateUri"])).read_value() is not None
        assert {"State", "Phase", "Step", "StepCount", "TimeLeftSeconds", "ActiveTableCrc", "LastCalibration",
                "LastRecheck", "StartCalibration", "StartRecheck", "Abort", "Acknowledge",
                "ResultManagement"} <= await _browse_names(node)
        assert await read(node, idx, "State") == "Idle"
        assert await read(node, idx, "LastCalibration", "RunId") == 0  # a new run database
        drift = await node.get_child([f"{idx}:LastRecheck", f"{idx}:DriftRmsMicrometre"])
        unit = await (await drift.get_child(["0:EngineeringUnits"])).read_value()
        assert (unit.UnitId, unit.DisplayName.Text) == (13384, "µm")  # UNECE 4H, OPC 10000-8 §5.6.3

        handler = Collector()
        await subscribe_station(client, idx, node, handler, "Step", "State", "TimeLeftSeconds")

        # --- a recheck without a calibration: the session refuses it, as at the terminal, before anything moves
        await node.call_method(f"{idx}:StartRecheck")
        refused = await asyncio.wait_for(handler.events.get(), 90)
        assert (refused.Verdict, refused.ExitCode, refused.RunId) == ("CONFIG_ERROR", 2, 0)
        assert "calibrate first" in json.loads(refused.Result.ResultContent[0].Value)["failure"]["message"]
        await node.call_method(f"{idx}:Acknowledge")

        # --- calibrate (the recheck's baseline), watched by a subscriber that is then killed
        dying = subprocess.Popen([sys.executable, "-c", DYING_CLIENT, served.url, str(pki.client_cert),
                                  str(pki.client_key), PASSWORDS["watch"]], stdout=subprocess.PIPE, text=True,
                                 env={**os.environ, "PYTHONPATH": str(Path.cwd())})
        try:
            assert dying.stdout is not None
            assert (await asyncio.to_thread(dying.stdout.readline)).strip() == "subscribed"
            await node.call_method(f"{idx}:StartCalibration")
            with pytest.raises(BadInvalidState):  # a second start during the run
                await node.call_method(f"{idx}:StartRecheck")
            assert "is active" in await read(node, idx, "LastRefusal")
            with pytest.raises(BadInvalidState):  # nothing to acknowledge while running
                await node.call_method(f"{idx}:Acknowledge")
            async def measuring() -> None:  # the dying subscriber sees the run measuring
                line = ""
                while not line.startswith("step") or line.split()[1] in ("0", "None"):
                    line = (await asyncio.to_thread(dying.stdout.readline)).strip()
                    assert line, "the dying subscriber saw no progress"

            await asyncio.wait_for(measuring(), 120)
            dying.send_signal(signal.SIGKILL)  # dies mid-subscription, its session open
            dying.wait(10)
            assert await read(node, idx, "State") == "Running"  # served while measuring
            await node.call_method(f"{idx}:Pause")  # the runner stops at its next safe point
            await asyncio.wait_for(_until(node, idx, "State", "Paused"), 60)
            with pytest.raises(BadInvalidState):
                await node.call_method(f"{idx}:StartRecheck")
            await node.call_method(f"{idx}:Resume")
            await asyncio.wait_for(_until(node, idx, "State", "Running"), 60)
            calibrated = await asyncio.wait_for(handler.events.get(), 150)
        finally:
            if dying.poll() is None:
                dying.kill()
        assert (calibrated.RunKind, calibrated.Verdict, calibrated.ExitCode) == ("calibration", "SUCCESS", 0)
        steps = [s for s in handler.values("Step") if s]
        assert any(0 < t < 3600 for t in handler.values("TimeLeftSeconds"))  # an estimate, in seconds
        # Step is k of StepCount counted in the order measured (docs/opcua.md), not the plan's index:
        # the locating touches come first and out of the plan's order (issue 37); a fresh run's
        # first step is 1 and k rises, through the pause, to StepCount at the last step
        count = await read(node, idx, "StepCount")
        assert len(steps) > 10 and steps[0] == 1 and steps[-1] == count, (steps[:5], steps[-3:], count)
        # strictly up (a value may be coalesced by the 20 ms publishing interval, never repeated or reversed)
        assert all(b > a for a, b in zip(steps, steps[1:])), steps
        assert await read(node, idx, "State") == "SUCCESS"
        assert await read(node, idx, "LastCalibration", "Gain") > 20
        assert len(await read(node, idx, "ActiveTableCrc")) == 8  # the table the calibration activated
        offsets = [await (await axes.get_child([f"{rob_ns}:Axis{j}", f"{idx}:IdentifiedOffset"])).read_value()
                   for j in (1, 2, 3, 4)]
        assert any(v == v for v in offsets)  # identified where the robot file's minimal set has them (not NaN)

        with pytest.raises(BadInvalidState):  # the outcome is latched until acknowledged
            await node.call_method(f"{idx}:StartRecheck")
        await node.call_method(f"{idx}:Acknowledge")
        assert await read(node, idx, "State") == "Idle"

        # --- the recheck and its verdict
        await node.call_method(f"{idx}:StartRecheck")
        ready = await asyncio.wait_for(handler.events.get(), 90)
        assert ready.RunKind == "recheck" and ready.Verdict in ("SUCCESS", "DRIFTED")
        assert ready.RunId == calibrated.RunId + 1
        meta = ready.Result.ResultMetaData
        assert meta.ResultId == f"run-{ready.RunId}" and meta.IsSimulated is True
        assert meta.ResultEvaluationCode == ready.ExitCode
        assert await read(node, idx, "LastRecheck", "Verdict") == ready.Verdict
        assert await read(node, idx, "LastRecheck", "BaselineRunId") == calibrated.RunId

        # --- the result, read back through the Machinery Result methods
        rns = await client.get_namespace_index("http://opcfoundation.org/UA/Machinery/Result/")
        results = await node.get_child([f"{rns}:ResultManagement"])
        handle, latest, error = await results.call_method(f"{rns}:GetLatestResult", ua.Variant(1000, ua.VariantType.Int32))
        assert error == 0 and latest.ResultMetaData.ResultId == meta.ResultId
        content = json.loads(latest.ResultContent[0].Value)
        assert content["outcome"] == ready.Verdict and content["kind"] == "recheck"
        assert content["baseline"]["run_id"] == calibrated.RunId
        _, first, _ = await results.call_method(f"{rns}:GetResultById", ua.Variant(f"run-{calibrated.RunId}"),
                                                 ua.Variant(1000, ua.VariantType.Int32))
        assert json.loads(first.ResultContent[0].Value)["gain"] > 20

        # --- a client outside this process reads the state: asyncua's uaread, as docs/opcua.md quotes it
        uaread = Path(sys.executable).with_name("uaread")
        out = await asyncio.to_thread(subprocess.run, [
            str(uaread), "-u", served.url, "--security", f"Basic256Sha256,SignAndEncrypt,{pki.client_cert},{pki.client_key}",
            "--user", "watch", "--password", PASSWORDS["watch"], "-n", f"ns={idx};s=CalibrationStation.State"],
            capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert out.stdout.strip() == ready.Verdict

        # --- Abort: the run stops at its next safe point and says so
        await node.call_method(f"{idx}:Acknowledge")
        with pytest.raises(BadInvalidState):
            await node.call_method(f"{idx}:Abort")  # nothing to abort
        await node.call_method(f"{idx}:StartRecheck")
        await node.call_method(f"{idx}:Abort")
        aborted = await asyncio.wait_for(handler.events.get(), 90)
        assert (aborted.Verdict, aborted.ExitCode) == ("ABORTED", 6)
        assert aborted.Result.ResultMetaData.ResultEvaluation == 0  # Undefined: no verdict
        await node.call_method(f"{idx}:Acknowledge")
        assert await read(node, idx, "LastRecheck", "RunId") == aborted.RunId  # the last recheck, as it ended
        assert await read(node, idx, "LastRecheck", "Verdict") == "ABORTED"
        assert await read(node, idx, "State") == "Idle"
    assert served.process.poll() is None  # still serving
