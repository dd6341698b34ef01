"""The address space from a cell's files: the published models load, and the robot, the body and
its CMM certificate are what the configuration says (asyncua's server in this process, no network)."""

from __future__ import annotations

import datetime as dt
import re
import shutil

from asyncua import Server, ua

from station.cell.config.cell_config import load_config
from station.ui.opcua.model import COMPANION_FILES, NODESET_DIR, build_instances, load_models
from station.ui.opcua.server import cell_facts, offset_parameters
from tests.opcua.clients import CONFIG


async def test_the_cells_files_fill_the_companion_models(tmp_path) -> None:
    cell = tmp_path / "cell"
    shutil.copytree(CONFIG.parent, cell)
    body = cell / "body.csv"
    body.write_text("# certificate_id: CMM-2026-0142\n# certificate_date: 2026-11-02\n" + body.read_text())
    cfg = load_config(str(cell / "cell.toml"))

    server = Server()
    await server.init()
    idx = await load_models(server)
    uris = await server.get_namespace_array()
    for name in COMPANION_FILES:  # every published model, by the URI its file declares
        model = re.search(r'<Model ModelUri="([^"]+)"', (NODESET_DIR / name).read_text(encoding="utf-8"))
        assert model is not None and model.group(1) in uris, name
    nodes = await build_instances(server, idx, cell_facts(cfg))

    ia = await server.get_namespace_index("http://opcfoundation.org/UA/IA/")
    certificate = server.get_node(ua.NodeId("CalibrationBody", idx))
    assert await (await certificate.get_child([f"{ia}:CertificateUri"])).read_value() == "CMM-2026-0142"
    date = await (await certificate.get_child([f"{ia}:LastValidationDate"])).read_value()
    assert date.replace(tzinfo=dt.timezone.utc) == dt.datetime(2026, 11, 2, tzinfo=dt.timezone.utc)
    assert len(nodes.axis_offsets) == 4  # one per joint of the robot file
    # each axis' offset parameter: the yaw of a revolute joint's transform, the z of a prismatic one
    specs = offset_parameters(cfg)
    names = [t.name for t in cfg.model.transforms if t.joint is not None]
    for spec, name, t in zip(specs, names, [t for t in cfg.model.transforms if t.joint is not None]):
        if spec is not None:
            suffix = "yaw" if str(t.joint) == "revolute" else "z"
            assert spec.index == cfg.model.param_index(f"{name}.{suffix}")
