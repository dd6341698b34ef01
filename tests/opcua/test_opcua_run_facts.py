"""The OPC UA service follows the run's stream (issue 42): LastCalibration, the active table's CRC
and the axes' identified offsets are the events' figures, read by a real client over
SignAndEncrypt from the server built as ``station serve --opcua`` builds it (in this process).
The run database is empty: nothing the client reads can have been read back from it."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.records.summary import (
    CorrectionSummary,
    ErrorStats,
    IdentificationSummary,
    ParameterEstimate,
    RunSummary,
    TableSummary,
    UploadSummary,
)
from station.cell.run.facts.events import Identified, RunFinished, RunStarted, TableDesigned, Uploaded, Verified
from station.errors import Outcome
from station.ui.opcua.server import ServeOptions, build_server, offset_parameters
from tests.opcua.clients import CONFIG, PASSWORDS, connected, read, station
from tests.opcua.conftest import free_port

pytestmark = [pytest.mark.timeout(300)]


async def _until(check, what: str) -> None:
    for _ in range(400):
        if await check():
            return
        await asyncio.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


async def test_the_client_reads_the_figures_the_run_streamed(pki, tmp_path) -> None:
    opts = ServeOptions(config=str(CONFIG), users=str(pki.users), pki=str(pki.root / "server"), host="127.0.0.1",
                        port=free_port(), simulated=True, db=str(tmp_path / "runs.sqlite"))
    server, service, url = await build_server(opts)
    cfg = load_config(CONFIG)
    specs = offset_parameters(cfg)
    params = np.asarray(cfg.model.nominal, dtype=float).copy()
    axis = next(i for i, s in enumerate(specs) if s is not None)
    spec = specs[axis]
    assert spec is not None
    index, scale = spec.index, spec.scale
    params[index] += 1.5e-3  # an identified zero offset of 1.5e-3 rad or mm beyond the nominal
    before = ErrorStats(n=24, rms_um=612.3, max_um=900.0, ap_max_um=700.0, rp_max_um=None)
    after = ErrorStats(n=24, rms_um=17.25, max_um=30.0, ap_max_um=20.0, rp_max_um=None)
    table = CorrectionSummary(n_values=31680, interpolation_bound_um=4.73, crc32="1a2b3c4d", grid_shape=(12, 11, 3, 8))
    # the offset's parameter among the chosen: a joint the minimal set does not hold reads NaN (39)
    ident = IdentificationSummary("pose", 48, 20, 1.0, 8.6, (),
                                  (ParameterEstimate(spec.name, float(params[index]), 1e-5),))
    upload = UploadSummary("1a2b3c4d", 1.9)
    summary = RunSummary(outcome=Outcome.TARGET_MISSED, run_id=5, correction=table, before=before, after=after,
                         upload=upload, tables=TableSummary("none", "1a2b3c4d"), identification=ident)
    async with server:
        await service.start()
        try:
            async with connected(url, pki.client_cert, pki.client_key, user="watch", password=PASSWORDS["watch"]) as client:
                idx, node = await station(client)
                assert await read(node, idx, "ActiveTableCrc") == "unknown"  # no run database yet
                assert math.isnan(await read(node, idx, "LastCalibration", "Gain"))
                assert math.isnan(await read(node, idx, "LastCalibration", "InterpolationBoundMicrometre"))
                for event in (RunStarted(5, 60), Identified(ident, tuple(float(v) for v in params)),
                              TableDesigned(table), Uploaded(upload, "1a2b3c4d", "none")):
                    service.stream(event)
                await _until(lambda: _is(read(node, idx, "ActiveTableCrc"), "1a2b3c4d"), "the uploaded table's CRC")
                offsets = [await client.get_node(n.nodeid).read_value() for n in service.nodes.axis_offsets]
                assert offsets[axis] == pytest.approx(1.5e-3 * scale)
                assert await read(node, idx, "LastCalibration", "RunId") == 0  # not ended: no record yet
                service.stream(Verified(before, after, summary.gain))
                service.stream(RunFinished(summary))
                await _until(lambda: _is(read(node, idx, "LastCalibration", "RunId"), 5), "LastCalibration")
                assert await read(node, idx, "LastCalibration", "Outcome") == "TARGET_MISSED"
                assert await read(node, idx, "LastCalibration", "ExitCode") == summary.exit_code == 10
                assert await read(node, idx, "LastCalibration", "RmsBeforeMicrometre") == 612.3
                assert await read(node, idx, "LastCalibration", "RmsAfterMicrometre") == 17.25
                assert await read(node, idx, "LastCalibration", "Gain") == summary.gain
                # the table's bound: the TableDesigned event's, the one the run judged and stored
                assert await read(node, idx, "LastCalibration", "InterpolationBoundMicrometre") == 4.73
                bound = await node.get_child([f"{idx}:LastCalibration", f"{idx}:InterpolationBoundMicrometre"])
                unit = await (await bound.get_child(["0:EngineeringUnits"])).read_value()
                assert unit.DisplayName.Text == "µm"
                assert await read(node, idx, "RunKind") == "calibration"
        finally:
            await service.stop()


async def _is(value, expected) -> bool:
    return await value == expected
