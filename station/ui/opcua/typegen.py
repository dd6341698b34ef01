"""Writes ``nodesets/Station.NodeSet2.xml``: the station's own types, in its own namespace.

The file is kept in the project and loaded like the OPC Foundation's files; this module is how
it was made (``python -m station.ui.opcua.typegen``), so that the XML comes from asyncua's
exporter instead of being typed by hand. The server never runs it.

Types (numeric ids fixed here, so that a PLC program may name them):
``CalibrationStationType`` (i=1001) the station's state, its run and its methods;
``RunRecordType`` (i=1002), ``CalibrationRecordType`` (i=1003), ``RecheckRecordType`` (i=1004)
the last calibration and recheck with their figures in engineering units;
``CalibrationResultReadyEventType`` (i=1005), a concrete ResultReadyEventType (OPC 40001-101
§8.2, abstract there) carrying the verdict.
"""

from __future__ import annotations

import asyncio
import datetime as dt
from pathlib import Path

from asyncua import Server, ua

from station.ui.opcua.model import NODESET_DIR, STATION_NS, load_companion_nodesets, node_id, result_ns, status

#: (browse name, variant type, description) of the station's variables
STATION_VARIABLES = (
    ("State", ua.VariantType.String, "Idle, Running, Paused, or the outcome of the run that ended (SUCCESS, "
                                     "DRIFTED, ABORTED, …) until it is acknowledged"),
    ("OutcomeCode", ua.VariantType.Int32, "the exit code of the outcome in State (docs/opcua.md); -1 while idle or running"),
    ("RunKind", ua.VariantType.String, "calibration or recheck: the active or last run"),
    ("RunId", ua.VariantType.Int64, "the active or last run's number in the run database (0: none)"),
    ("Phase", ua.VariantType.String, "connect, plan, measure, identify, correct, upload, verify, done"),
    ("Step", ua.VariantType.UInt32, "the step being measured, 1 … StepCount, counted in the order the run measures its steps (not the plan's index)"),
    ("StepCount", ua.VariantType.UInt32, "the steps of the run's plan"),
    ("TimeLeftSeconds", ua.VariantType.Double, "estimated time to the end of the measurement [s]"),
    ("ActiveTableCrc", ua.VariantType.String, "CRC-32 (hex) of the correction table active on the controller as the "
                                              "run database last saw it; 'none' without a table"),
    ("LastRefusal", ua.VariantType.String, "why the last method call was refused"),
    ("Message", ua.VariantType.String, "the run's last notice"),
)
RECORD_VARIABLES = (
    ("RunId", ua.VariantType.Int64, "run number (0: none yet)"),
    ("Outcome", ua.VariantType.String, "the outcome's name"),
    ("ExitCode", ua.VariantType.Int32, "the outcome's exit code"),
    ("FinishedUtc", ua.VariantType.DateTime, "when the run was created (UTC)"),
)
CALIBRATION_VARIABLES = (
    ("RmsBeforeMicrometre", ua.VariantType.Double, "verification RMS position error before correction [µm]"),
    ("RmsAfterMicrometre", ua.VariantType.Double, "verification RMS position error after correction [µm]"),
    ("Gain", ua.VariantType.Double, "before / after"),
    ("InterpolationBoundMicrometre", ua.VariantType.Double,
     "the correction table's interpolation bound [µm], the one the run judged against its limit and stored"),
)
RECHECK_VARIABLES = (
    ("Verdict", ua.VariantType.String, "SUCCESS (within tolerance), DRIFTED, RECHECK_UNTRUSTED or a failure"),
    ("BaselineRunId", ua.VariantType.Int64, "the calibration it was compared with"),
    ("DriftRmsMicrometre", ua.VariantType.Double, "RMS position drift since the baseline [µm]"),
    ("DriftMaxMicrometre", ua.VariantType.Double, "largest position drift [µm]"),
    ("ToleranceMicrometre", ua.VariantType.Double, "the RMS drift tolerance [µm]"),
)
METHODS = ("StartCalibration", "StartRecheck", "Abort", "Acknowledge", "Pause", "Resume")
EVENT_PROPERTIES = (
    ("Verdict", ua.VariantType.String), ("ExitCode", ua.VariantType.Int32),
    ("RunId", ua.VariantType.Int64), ("RunKind", ua.VariantType.String),
)


#: the initial value of each kind (a non-array Variant cannot be empty)
_INITIAL = {ua.VariantType.String: "", ua.VariantType.Int32: -1, ua.VariantType.Int64: 0, ua.VariantType.UInt32: 0,
            ua.VariantType.Double: float("nan"), ua.VariantType.DateTime: dt.datetime(1601, 1, 1, tzinfo=dt.timezone.utc)}


async def _variables(parent, idx: int, first: int, table) -> None:
    for i, (name, vtype, text) in enumerate(table):
        var = await parent.add_variable(node_id(first + i, idx), ua.QualifiedName(name, idx), ua.Variant(_INITIAL[vtype], vtype),
                                        varianttype=vtype)
        await var.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(ua.LocalizedText(text))))
        await var.set_modelling_rule(True)


async def build(server: Server) -> int:
    """Add the station's types to ``server`` (the companion nodesets loaded); its namespace index."""
    idx = await server.register_namespace(STATION_NS)
    base = server.get_node(ua.ObjectIds.BaseObjectType)
    record = await base.add_object_type(node_id(1002, idx), ua.QualifiedName("RunRecordType", idx))
    await _variables(record, idx, 6100, RECORD_VARIABLES)
    cal = await record.add_object_type(node_id(1003, idx), ua.QualifiedName("CalibrationRecordType", idx))
    await _variables(cal, idx, 6200, CALIBRATION_VARIABLES)
    rec = await record.add_object_type(node_id(1004, idx), ua.QualifiedName("RecheckRecordType", idx))
    await _variables(rec, idx, 6300, RECHECK_VARIABLES)
    station = await base.add_object_type(node_id(1001, idx), ua.QualifiedName("CalibrationStationType", idx))
    await _variables(station, idx, 6001, STATION_VARIABLES)
    for i, (name, typ) in enumerate((("LastCalibration", cal), ("LastRecheck", rec))):
        obj = await station.add_object(node_id(5001 + i, idx), ua.QualifiedName(name, idx), objecttype=typ.nodeid)
        await obj.set_modelling_rule(True)
        for child in await obj.get_children():  # the declaration's own variables: instantiated with the station
            await child.set_modelling_rule(True)
    for i, name in enumerate(METHODS):
        method = await station.add_method(node_id(7001 + i, idx), ua.QualifiedName(name, idx), _never, [], [])
        await method.set_modelling_rule(True)
    rns = await result_ns(server)
    ready = server.get_node(node_id(1002, rns))  # ResultReadyEventType
    event = await ready.add_object_type(node_id(1005, idx), ua.QualifiedName("CalibrationResultReadyEventType", idx))
    for i, (name, vtype) in enumerate(EVENT_PROPERTIES):
        prop = await event.add_property(node_id(6400 + i, idx), ua.QualifiedName(name, idx), ua.Variant(_INITIAL[vtype], vtype),
                                        varianttype=vtype)
        await prop.set_modelling_rule(True)
    return idx


def _never(parent: ua.NodeId) -> ua.StatusCode:  # the server links its own callbacks to the instances
    return status(ua.StatusCodes.BadNotImplemented)


#: the model's version: raise it with every change of the types above
MODEL_VERSION = "1.1.0"
MODEL_DATE = "2026-12-07T00:00:00Z"


async def write(path: Path) -> None:
    server = Server()
    await server.init()
    await load_companion_nodesets(server)
    idx = await build(server)
    await server.export_xml_by_ns(str(path), [idx], export_values=True)  # the values give the event fields their types
    # asyncua's exporter writes no <Models>; other tools (model compilers, UaExpert) want the model's
    # identity and what it requires (OPC 10000-6 §F.2)
    text = path.read_text(encoding="utf-8")
    models = (f'  <Models>\n    <Model ModelUri="{STATION_NS}" Version="{MODEL_VERSION}" PublicationDate="{MODEL_DATE}">\n'
              f'      <RequiredModel ModelUri="http://opcfoundation.org/UA/" Version="1.05.02" PublicationDate="2022-11-01T00:00:00Z" />\n'
              f'      <RequiredModel ModelUri="http://opcfoundation.org/UA/Machinery/Result/" Version="1.00.0" '
              f'PublicationDate="2023-01-01T00:00:00Z" />\n    </Model>\n  </Models>\n')
    path.write_text(text.replace("  </NamespaceUris>\n", "  </NamespaceUris>\n" + models, 1), encoding="utf-8")


if __name__ == "__main__":
    asyncio.run(write(NODESET_DIR / "Station.NodeSet2.xml"))
