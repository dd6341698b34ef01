"""The address space: the OPC Foundation's companion models, the station's own types, and the
instances of one cell (its robot, its calibration body, the station).

Load order follows each file's ``<RequiredModel>`` (nodesets/README.md): DI, Machinery, IA,
Robotics, Machinery Result, then the station's own ``Station.NodeSet2.xml``. The files are read
as they came from the OPC Foundation; the one change is made in memory:
:func:`_decodable_text` leaves out default values asyncua's XML importer cannot decode (an
ExtensionObject inside an ExtensionObject: ResultType's and two of its instance declarations'
in the Machinery Result file). Those are *initial values* of type definitions, not nodes; the
nodes and their references all load.
"""

from __future__ import annotations

import datetime as dt
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asyncua import Node, Server, ua

NODESET_DIR = Path(__file__).parent / "nodesets"
#: the station's own namespace (its types in Station.NodeSet2.xml, its instances)
STATION_NS = "urn:robot-calibration-station:opcua:station"
DI_NS = "http://opcfoundation.org/UA/DI/"
ROBOTICS_NS = "http://opcfoundation.org/UA/Robotics/"
IA_NS = "http://opcfoundation.org/UA/IA/"
RESULT_NS = "http://opcfoundation.org/UA/Machinery/Result/"
#: in dependency order (each file's <RequiredModel> entries come before it)
COMPANION_FILES = ("Opc.Ua.Di.NodeSet2.xml", "Opc.Ua.Machinery.NodeSet2.xml", "Opc.Ua.IA.NodeSet2.xml",
                   "Opc.Ua.Robotics.NodeSet2.xml", "Opc.Ua.Machinery.Result.NodeSet2.xml")
STATION_FILE = "Station.NodeSet2.xml"

_UANODESET = "{http://opcfoundation.org/UA/2011/03/UANodeSet.xsd}"
_TYPES = "{http://opcfoundation.org/UA/2008/02/Types.xsd}"

# numeric ids of the companion types used here (each file's NodeIds.csv)
ROBOTICS_MOTION_DEVICE_SYSTEM = 1002  # MotionDeviceSystemType, OPC 40010-1 §7.1
ROBOTICS_MOTION_DEVICE = 1004  # MotionDeviceType, OPC 40010-1 §7.2
ROBOTICS_AXIS = 16601  # AxisType, OPC 40010-1 §7.5
IA_CALIBRATION_TARGET = 1019  # CalibrationTargetType, OPC 10000-200 §7
RESULT_MANAGEMENT = 1004  # ResultManagementType, OPC 40001-101 §8.3
MACHINERY_NS = "http://opcfoundation.org/UA/Machinery/"
MACHINES_FOLDER = 1001  # Objects/Machines, OPC 40001-1 §9.2: "all machines are directly referenced by this object"
# the station's own (Station.NodeSet2.xml, station.ui.opcua.typegen)
STATION_TYPE = 1001
#: the station's methods (operators only)
OPERATOR_METHODS = ("StartCalibration", "StartRecheck", "Abort", "Acknowledge", "Pause", "Resume")
RESULT_READY_EVENT = 1005


def node_id(identifier: int | str, ns: int) -> ua.NodeId:
    """asyncua's NodeId, its fields in asyncua's declared types (mypy), the values unchanged."""
    return ua.NodeId(ua.String(identifier) if isinstance(identifier, str) else ua.Int32(identifier), ua.Int16(ns))


def status(code: int) -> ua.StatusCode:
    """A status code (``ua.StatusCodes.…``) as asyncua's StatusCode."""
    return ua.StatusCode(ua.UInt32(code))


def _decodable_text(path: Path) -> tuple[str, list[str]]:
    """The file's text without the default values asyncua cannot decode; the NodeIds whose value
    was left out."""
    root = ET.parse(path).getroot()
    dropped = []
    for node in root:
        value = node.find(_UANODESET + "Value")
        if value is None:
            continue
        for ext in value.iter(_TYPES + "ExtensionObject"):
            body = ext.find(_TYPES + "Body")
            if body is not None and any(e.tag == _TYPES + "TypeId" for e in body.iter()):
                node.remove(value)
                dropped.append(str(node.get("NodeId")))
                break
    return ET.tostring(root, encoding="unicode"), dropped


async def load_companion_nodesets(server: Server) -> None:
    """DI, Machinery, IA, Robotics and Machinery Result, as published (see the module's note)."""
    for name in COMPANION_FILES:
        text, _ = _decodable_text(NODESET_DIR / name)
        await server.import_xml(xmlstring=text)


async def result_ns(server: Server) -> int:
    return int(await server.get_namespace_index(RESULT_NS))


async def load_models(server: Server) -> int:
    """Every model file; the station namespace's index."""
    await load_companion_nodesets(server)
    await server.import_xml(str(NODESET_DIR / STATION_FILE))
    return int(await server.get_namespace_index(STATION_NS))


@dataclass(frozen=True)
class CellFacts:
    """What the address space says of the cell, from the user's configuration (nothing invented:
    an empty string where the files say nothing)."""

    cell: str
    robot_model: str
    robot_description: str
    robot_serial: str
    controller: str
    axes: tuple[tuple[str, str], ...]  # (name, 'revolute' | 'prismatic') per joint
    body_certificate_id: str
    body_certificate_date: str  # YYYY-MM-DD or ""
    body_points: int


@dataclass
class StationNodes:
    """The nodes the service writes and links."""

    idx: int
    station: Node
    variables: dict[str, Node]  # the station's own, by browse name
    last_calibration: dict[str, Node]
    last_recheck: dict[str, Node]
    methods: dict[str, list[Node]]  # browse name -> the instance's method node and the type's
    axis_offsets: list[Node]
    result_management: Node
    result_methods: dict[str, list[Node]]
    event_type: Node


async def _children(node: Node) -> dict[str, Node]:
    out: dict[str, Node] = {}
    for child in await node.get_children():
        out[(await child.read_browse_name()).Name] = child
    return out


async def _drop_placeholders(node: Node) -> None:
    """Delete the ``<Name>`` placeholders asyncua instantiated from a type's MandatoryPlaceholder
    declarations (OPC 10000-3 §6.4.4.4.4: a placeholder stands for instances, it is never one)."""
    for child in await node.get_children():
        name = (await child.read_browse_name()).Name
        if name.startswith("<") and name.endswith(">"):
            await child.delete(recursive=True)
        elif child.nodeid.NamespaceIndex == node.nodeid.NamespaceIndex:  # the instance's own subtree only
            await _drop_placeholders(child)


async def _property(parent: Node, idx: int, name: str, value: object, vtype: ua.VariantType, text: str) -> Node:
    prop = await parent.add_property(idx, name, ua.Variant(value, vtype))
    await prop.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(ua.LocalizedText(text))))
    return prop


async def _set(node: Node, value: object, vtype: ua.VariantType) -> None:
    await node.write_value(ua.DataValue(ua.Variant(value, vtype)))


def eu_information(code: str, symbol: str, text: str) -> ua.EUInformation:
    """A UNECE unit as OPC 10000-8 §5.6.3 encodes it: UnitId is the code's characters as bytes
    of an Int32 (e.g. 'MMT' millimetre, 'DD' degree, '4H' micrometre)."""
    unit_id = 0
    for ch in code:
        unit_id = (unit_id << 8) | ord(ch)
    return ua.EUInformation(NamespaceUri="http://www.opcfoundation.org/UA/units/un/cefact", UnitId=unit_id,
                            DisplayName=ua.LocalizedText(symbol), Description=ua.LocalizedText(text))


async def build_instances(server: Server, idx: int, facts: CellFacts) -> StationNodes:
    """Instantiate the robot, the calibration body and the station under Objects."""
    objects = server.nodes.objects
    rob = await server.get_namespace_index(ROBOTICS_NS)
    ia = await server.get_namespace_index(IA_NS)
    rns = await result_ns(server)

    # the robot: OPC 40010-1 MotionDeviceSystemType with one MotionDeviceType and its axes
    system = await objects.add_object(node_id("Robot", idx), ua.QualifiedName("Robot", idx),
                                      objecttype=node_id(ROBOTICS_MOTION_DEVICE_SYSTEM, rob), instantiate_optional=False)
    devices = (await _children(system))["MotionDevices"]
    device = await devices.add_object(node_id("Robot.MotionDevice", idx), ua.QualifiedName(facts.robot_model or "robot", rob),
                                      objecttype=node_id(ROBOTICS_MOTION_DEVICE, rob), instantiate_optional=False)
    props = await _children(device)
    await _set(props["Manufacturer"], ua.LocalizedText(""), ua.VariantType.LocalizedText)
    await _set(props["Model"], ua.LocalizedText(facts.robot_model), ua.VariantType.LocalizedText)
    await _set(props["ProductCode"], facts.robot_description, ua.VariantType.String)
    await _set(props["SerialNumber"], facts.robot_serial, ua.VariantType.String)
    axes = props["Axes"]
    offsets = []
    for j, (name, kind) in enumerate(facts.axes, start=1):
        axis = await axes.add_object(node_id(f"Robot.Axis{j}", idx), ua.QualifiedName(name, rob),
                                     objecttype=node_id(ROBOTICS_AXIS, rob), instantiate_optional=False)
        unit = eu_information("DD", "°", "degree") if kind == "revolute" else eu_information("MMT", "mm", "millimetre")
        off = await axis.add_variable(node_id(f"Robot.Axis{j}.IdentifiedOffset", idx),
                                      ua.QualifiedName("IdentifiedOffset", idx), ua.Variant(float("nan"), ua.VariantType.Double))
        await off.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(ua.LocalizedText(
            f"joint {j}'s zero offset identified by the last calibration, identified minus nominal "
            f"[{'degree' if kind == 'revolute' else 'mm'}]; NaN where the calibration did not identify it on its own "
            f"(it merged into another parameter) or none ran yet"))))
        await _property(off, 0, "EngineeringUnits", unit, ua.VariantType.ExtensionObject, "unit of the value")
        offsets.append(off)

    # the calibration body: OPC 10000-200 §7 CalibrationTargetType, its CMM certificate
    body = await objects.add_object(node_id("CalibrationBody", idx), ua.QualifiedName("CalibrationBody", idx),
                                    objecttype=node_id(IA_CALIBRATION_TARGET, ia), instantiate_optional=False)
    await _property(body, ia, "CertificateUri", facts.body_certificate_id, ua.VariantType.String,
                    "the body's CMM certificate as the [body] file names it")
    if facts.body_certificate_date:  # optional in the type: absent where the [body] file gives no date
        date = dt.datetime.fromisoformat(facts.body_certificate_date).replace(tzinfo=dt.timezone.utc)
        await _property(body, ia, "LastValidationDate", date, ua.VariantType.DateTime,
                        "the date of the body's CMM certificate")
    await _property(body, idx, "MeasuredPoints", facts.body_points, ua.VariantType.UInt32,
                    "the body's points (cube corners) the CMM report gives")

    # the station: its own type (Station.NodeSet2.xml), with result management inside it
    station_type = server.get_node(node_id(STATION_TYPE, idx))
    station = await objects.add_object(node_id("CalibrationStation", idx), ua.QualifiedName("CalibrationStation", idx),
                                       objecttype=station_type.nodeid, instantiate_optional=False)
    children = await _children(station)
    type_children = await _children(station_type)
    methods = {name: [children[name], type_children[name]] for name in OPERATOR_METHODS}
    results = await station.add_object(node_id("CalibrationStation.Results", idx), ua.QualifiedName("ResultManagement", rns),
                                       objecttype=node_id(RESULT_MANAGEMENT, rns), instantiate_optional=False)
    result_type = await _children(server.get_node(node_id(RESULT_MANAGEMENT, rns)))
    result_children = await _children(results)
    result_methods = {}
    for name in ("GetLatestResult", "GetResultById"):
        nodes = [n for n in (result_children.get(name), result_type.get(name)) if n is not None]
        if name not in result_children:  # optional in the type: add the instance's own, with the type's arguments
            nodes.insert(0, await _copy_method(results, result_type[name], rns))
        result_methods[name] = nodes
    await station.add_reference(results.nodeid, ua.ObjectIds.GeneratesEvent, forward=True)  # noqa: B018
    for top in (system, body, station):
        await _drop_placeholders(top)
    # the robot and the station are the machines of this server (OPC 40001-1 §9.2; OPC 40010-1 §6:
    # a MotionDeviceSystem is a machine); the body is a target they use, not a machine
    machines = server.get_node(node_id(MACHINES_FOLDER, await server.get_namespace_index(MACHINERY_NS)))
    for machine in (system, station):
        await machines.add_reference(machine.nodeid, ua.ObjectIds.Organizes, forward=True)  # noqa: B018
    variables = {k: v for k, v in children.items() if k not in methods and k not in ("LastCalibration", "LastRecheck")}
    last_calibration = await _children(children["LastCalibration"])
    last_recheck = await _children(children["LastRecheck"])
    for name, node in [*variables.items(), *last_calibration.items(), *last_recheck.items()]:
        if name.endswith("Micrometre"):
            await _property(node, 0, "EngineeringUnits", eu_information("4H", "µm", "micrometre"),
                            ua.VariantType.ExtensionObject, "unit of the value")
        elif name.endswith("Seconds"):
            await _property(node, 0, "EngineeringUnits", eu_information("SEC", "s", "second"),
                            ua.VariantType.ExtensionObject, "unit of the value")
    return StationNodes(idx=idx, station=station, variables=variables,
                        last_calibration=last_calibration, last_recheck=last_recheck,
                        methods=methods, axis_offsets=offsets, result_management=results,
                        result_methods=result_methods,
                        event_type=server.get_node(node_id(RESULT_READY_EVENT, idx)))


@dataclass(frozen=True)
class OffsetParameter:
    """The parameter that is a joint's zero offset: its index in the model's vector, its name,
    its nominal value and the factor to the unit shown (degrees for an angle, 1 for mm)."""

    index: int
    name: str
    nominal: float
    scale: float


def identified_offsets(identification: dict[str, Any] | None,
                       specs: list[OffsetParameter | None]) -> list[float]:
    """Per axis: identified minus nominal, in the unit shown; NaN (docs/opcua.md) where no
    calibration identified yet, the robot file gives the joint no offset parameter, or the
    calibration did not choose it (its effect merged into another parameter: the vector then
    holds the nominal, and a 0.0 would read as "identified, no offset")."""
    if identification is None:
        return [float("nan")] * len(specs)
    params = identification.get("params")
    chosen = set(identification.get("chosen") or ())
    out = []
    for spec in specs:
        value = float("nan")
        if spec is not None and spec.name in chosen and params is not None and spec.index < len(params):
            value = (float(params[spec.index]) - spec.nominal) * spec.scale
        out.append(value)
    return out


async def _copy_method(parent: Node, declaration: Node, ns: int) -> Node:
    """An optional method of a type, on the instance: the same browse name and arguments."""
    args = await _children(declaration)
    inputs = await args["InputArguments"].read_value() if "InputArguments" in args else []
    outputs = await args["OutputArguments"].read_value() if "OutputArguments" in args else []
    name = (await declaration.read_browse_name()).Name
    method = await parent.add_method(node_id(f"CalibrationStation.Results.{name}", parent.nodeid.NamespaceIndex),
                                     ua.QualifiedName(name, ns), _unlinked, inputs, outputs)
    await method.add_reference(declaration.nodeid, ua.ObjectIds.HasTypeDefinition, forward=True)  # noqa: B018
    return method


def _unlinked(parent: ua.NodeId, *args: object) -> ua.StatusCode:
    return status(ua.StatusCodes.BadNotImplemented)
