"""A run's Digital Calibration Certificate over OPC UA (issue 41): once 'station export-dcc' has
written it, GetResultById and GetLatestResult return it as the result's second ResultContent, a
ByteString holding the file's bytes (OPC 40001-101 §10.5: ResultContent is the result's data,
BaseDataType[]); a real asyncua client over the secured endpoint reads it, and it validates
against the kept DCC schema."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from asyncua import ua

from station.ui.cli.main import main
from station.ui.report.dcc import validate_dcc
from tests.opcua.clients import CONFIG, PASSWORDS, connected, station
from tests.opcua.conftest import Pki, Served, serving
from tests.short_plan import example_short
from tests.ui.test_export_dcc import ISSUER

RESULT_NS = "http://opcfoundation.org/UA/Machinery/Result/"


@pytest.fixture(scope="module")
def certified_server(pki: Pki, tmp_path_factory) -> Iterator[tuple[Served, Path]]:
    """A simulated calibration of the served cell with its certificate exported, then
    ``station serve --opcua`` over that run database. The cell is examples/scara600 with one visit
    per identification pose and one verification cycle: what is tested is how the certificate
    travels, which the example's full plan (three times the CPU) shows alike (issue 42)."""
    work = tmp_path_factory.mktemp("serve-dcc")
    cell = example_short(CONFIG, work)
    db, issuer, out = work / "runs.sqlite", work / "issuer.toml", work / "run1.xml"
    assert main(["calibrate", str(cell), "--simulated", "--seed", "1", "--db", str(db)]) == 0
    issuer.write_text(ISSUER)
    assert main(["export-dcc", "1", "--db", str(db), "--issuer", str(issuer), "-o", str(out)]) == 0
    with serving(pki, work, db, cell) as served:
        yield served, out


@pytest.mark.slow
@pytest.mark.timeout(400)
async def test_the_result_carries_the_exported_certificate(certified_server, pki) -> None:
    served, out = certified_server
    async with connected(served.url, pki.client_cert, pki.client_key, user="watch", password=PASSWORDS["watch"]) as c:
        _, node = await station(c)
        rns = await c.get_namespace_index(RESULT_NS)
        results = await node.get_child([f"{rns}:ResultManagement"])
        await c.load_data_type_definitions()
        _, by_id, error = await results.call_method(f"{rns}:GetResultById", ua.Variant("run-1"),
                                                    ua.Variant(1000, ua.VariantType.Int32))
        _, latest, _ = await results.call_method(f"{rns}:GetLatestResult", ua.Variant(1000, ua.VariantType.Int32))
    assert error == 0 and by_id.ResultMetaData.ResultId == "run-1" == latest.ResultMetaData.ResultId
    for result in (by_id, latest):
        summary, certificate = result.ResultContent
        assert json.loads(summary.Value)["run_id"] == 1  # [0] stays the run's --json
        assert certificate.VariantType == ua.VariantType.ByteString
        assert certificate.Value == out.read_bytes()  # the exported file, byte for byte
        validate_dcc(certificate.Value)  # offline, against the kept XSD files
