"""A record's RunId is written last (issue 42): the service writes LastCalibration's values one by
one, and a client that sees the new RunId (a line's MES subscribes to it, a test waits on it) then
reads that run's figures, never the previous run's beside the new number."""

from __future__ import annotations

import asyncio

import pytest

from station.cell.records.summary import CorrectionSummary, ErrorStats, RunSummary
from station.cell.run.facts.events import RunFinished, RunStarted
from station.errors import Outcome
from station.ui.opcua.server import ServeOptions, build_server
from tests.opcua.clients import CONFIG
from tests.opcua.conftest import free_port

pytestmark = [pytest.mark.timeout(300)]


def recorded(service) -> list[tuple[str, object]]:
    """(name, value) of each LastCalibration value the service writes, in order."""
    names = {node.nodeid: name for name, node in service.nodes.last_calibration.items()}
    writes: list[tuple[str, object]] = []
    write = service.server.write_attribute_value

    async def spy(nodeid, datavalue, *args, **kwargs):
        if nodeid in names:
            writes.append((names[nodeid], datavalue.Value.Value))
        return await write(nodeid, datavalue, *args, **kwargs)

    service.server.write_attribute_value = spy
    return writes


async def test_the_streamed_end_writes_lastcalibration_s_runid_after_its_figures(pki, tmp_path) -> None:
    opts = ServeOptions(config=str(CONFIG), users=str(pki.users), pki=str(pki.root / "server"), host="127.0.0.1",
                        port=free_port(), simulated=True, db=str(tmp_path / "runs.sqlite"))
    server, service, _ = await build_server(opts)
    stats = ErrorStats(n=24, rms_um=17.25, max_um=30.0, ap_max_um=20.0, rp_max_um=None)
    summary = RunSummary(outcome=Outcome.SUCCESS, run_id=5, before=stats, after=stats,
                         correction=CorrectionSummary(n_values=8, interpolation_bound_um=4.73, crc32="1a2b3c4d",
                                                      grid_shape=(2, 2, 2, 1)))
    async with server:
        await service.start()
        try:
            writes = recorded(service)
            service.stream(RunStarted(5, 60))
            service.stream(RunFinished(summary))
            for _ in range(400):  # the pump writes in the server's loop: yield to it until the record is whole
                if ("RunId", 5) in writes:
                    break
                await asyncio.sleep(0.02)
        finally:
            await service.stop()
    names = [name for name, _ in writes]
    assert names[-1] == "RunId" and writes[-1] == ("RunId", 5), names
    assert {"Outcome", "ExitCode", "Gain", "RmsAfterMicrometre", "InterpolationBoundMicrometre"} <= set(names[:-1])
    assert dict(writes)["InterpolationBoundMicrometre"] == 4.73
