"""A URDF robot's ``<collision>`` shapes in the collision check (issue 40): boxes, cylinders and meshes
ride on their links in place of the default capsules (poses the capsules would pass collide, and the
other way round), and a mesh file that is not found is refused, never skipped."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.config.sections import ObstacleConfig
from station.cell.plan.collision import check_path
from station.cell.plan.collision_shapes import cell_shapes, default_radii
from station.errors import ConfigError
from station.io.robot.collision import CollisionSpec
from station.io.robot.urdf_collision import urdf_link_geometry

pytest.importorskip("fcl")

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

#: a two-joint arm (metres): the base a 0.2 × 0.2 × 0.4 box, joint 1 at 0.5 m up about z, link 1 a
#: thin bar 0.4 m along x (2 cm across), joint 2 at its end about z, link 2 a fat cylinder (radius
#: 0.15 m) 0.3 m along x to the flange; LINK2 is replaced by a mesh in the mesh tests
LINK2 = '<origin xyz="0.15 0 0" rpy="0 1.5707963267948966 0"/><geometry><cylinder radius="0.15" length="0.3"/></geometry>'
URDF = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"><collision><origin xyz="0 0 0.2"/><geometry><box size="0.2 0.2 0.4"/></geometry></collision></link>
  <link name="l1"><collision><origin xyz="0.2 0 0"/><geometry><box size="0.4 0.02 0.02"/></geometry></collision></link>
  <link name="l2"><collision>{link2}</collision></link>
  <link name="flange"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.5"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.4 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3"/></joint>
  <joint name="j3" type="fixed"><parent link="l2"/><child link="flange"/><origin xyz="0.3 0 0"/></joint>
</robot>
"""


def _cell(folder: Path, link2: str = LINK2) -> Path:
    """The puma560 example's body with the arm above, 3 m away (out of the test's way), and the built-in
    head on the URDF's flange (a head file's frame would be in the last joint's frame)."""
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(EXAMPLES / "puma560" / "body.csv", folder / "body.csv")
    (folder / "arm.urdf").write_text(URDF.format(link2=link2), encoding="utf-8")
    text = (EXAMPLES / "puma560" / "cell.toml").read_text(encoding="utf-8")
    out = []
    for line in text.splitlines():
        if line.startswith("model = "):
            line = 'model = "arm.urdf"'
        elif line.startswith("setup = "):
            line = "setup = [-3000.0, 0.0, 0.0, 0.0, 0.0, 0.0]"
        elif line.startswith("joints = "):
            line = "joints = [[-170.0, 170.0], [-170.0, 170.0]]"
        elif line.startswith("park_joints") or line in ("[head]", 'file = "head.toml"'):
            continue
        out.append(line)
    (folder / "cell.toml").write_text("\n".join(out) + "\n", encoding="utf-8")
    return folder / "cell.toml"


def _with_box(cfg, name: str, centre_mm, size_mm):
    pose = np.eye(4)
    pose[:3, 3] = centre_mm
    return dataclasses.replace(cfg, obstacles=(ObstacleConfig(name, "box", "base", pose, tuple(size_mm)),))


def _capsules(cfg):
    """The same cell with the URDF's shapes left out: the default capsules."""
    return dataclasses.replace(cfg, robot_collision=CollisionSpec())


def _at(cfg, q_deg):
    return check_path(cfg, [(np.radians(q_deg), "step 1: approach", -1)]).clash


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    return load_config(_cell(tmp_path_factory.mktemp("arm")))


def test_the_urdf_shapes_replace_the_links_capsules(arm):
    shapes, _ = cell_shapes(arm)
    links = {s.group: s for s in shapes.moving if s.group.startswith("link:") and s.name != "head mount"}
    assert [(g, s.kind) for g, s in links.items()] == [("link:R", "box"), ("link:A1", "box"), ("link:A2", "cylinder")]
    assert links["link:A2"].size == pytest.approx((150.0, 300.0))
    # link 2's cylinder lies along x of its link (the URDF's rpy), centred 150 mm out: in the station
    # frame it rides on, its axis along the link and its centre 150 mm from joint 2
    assert abs(links["link:A2"].local[:3, 2] @ [1.0, 0.0, 0.0]) == pytest.approx(1.0)
    # the short-link rule is the capsules': the base and link 2 stay checked over link 1's thin bar
    assert frozenset(("link:R", "link:A2")) not in shapes.allowed
    assert frozenset(("link:R", "link:A1")) in shapes.allowed  # neighbours, as before
    # the head's mount (from joint 2's axis to the head) is part of the last link where the URDF gives it
    [mount] = [s for s in shapes.moving if s.name == "head mount"]
    assert mount.group == "link:A2"


def test_a_thin_box_passes_where_the_capsule_collides(arm):
    # a block 25 mm beside link 1's axis: its 10 mm half-width clears it, the default capsule does not
    cfg = _with_box(arm, "block", (200.0, 45.0, 500.0), (100.0, 40.0, 40.0))
    assert _at(cfg, [0.0, 0.0]) is None
    clash = _at(_capsules(cfg), [0.0, 0.0])
    assert clash is not None and "obstacle 'block'" in (clash.a, clash.b)
    assert clash.clearance_mm == pytest.approx(25.0 - default_radii(arm)[1], abs=0.5)


def test_a_fat_cylinder_collides_where_the_capsule_passes_and_moves_with_its_joint(arm):
    # a lid 100 mm above link 2's axis: inside its 150 mm cylinder, 58 mm clear of the 42 mm capsule
    cfg = _with_box(arm, "lid", (600.0, 0.0, 620.0), (60.0, 60.0, 40.0))
    assert _capsules(cfg) is not cfg and _at(_capsules(cfg), [0.0, 0.0]) is None
    clash = _at(cfg, [0.0, 0.0])
    assert clash is not None
    assert {clash.a, clash.b} == {"link A2 (l2's cylinder)", "obstacle 'lid'"}
    assert clash.clearance_mm == pytest.approx(-50.0, abs=1.0)  # 150 mm radius, face 100 mm above the axis
    assert _at(cfg, [0.0, -90.0]) is None  # link 2 turned away with its joint: clear
    # the path from one side to the other sweeps the cylinder through the lid: found between the ends
    # (the path's step bounds the motion of the cylinder's far rim, 150 mm off its link's line)
    assert _at(cfg, [0.0, 90.0]) is None
    swing = check_path(cfg, [(np.radians([0.0, -90.0]), "step 1: approach", -1),
                             (np.radians([0.0, 90.0]), "step 2: approach", -1)])
    assert swing.clash is not None and "on the move from step 1: approach" in swing.clash.where
    assert "link A2 (l2's cylinder)" in (swing.clash.a, swing.clash.b)


def _stl(path: Path) -> None:
    """Link 2's body as a mesh in millimetres (the URDF scales it by 0.001): a 300 × 300 × 300 mm block
    from the joint to the flange, 1000 triangles short of nothing: trimesh's box."""
    import trimesh

    block = trimesh.creation.box(extents=(300.0, 300.0, 300.0))
    block.apply_translation((150.0, 0.0, 0.0))
    path.parent.mkdir(parents=True, exist_ok=True)
    block.export(path)


MESH = ('<geometry><mesh filename="package://arm_description/meshes/l2.stl" scale="0.001 0.001 0.001"/>'
        '</geometry>')


def test_a_mesh_from_a_package_beside_the_urdf_is_used(tmp_path):
    pkg = tmp_path / "arm_description"
    _stl(pkg / "meshes" / "l2.stl")
    cfg = load_config(_cell(pkg / "urdf", MESH))
    geo = [g for g in cfg.robot_collision.geometry if g.kind == "mesh"]
    assert len(geo) == 1 and geo[0].missing is None and geo[0].link == "A2"
    assert np.ptp(geo[0].vertices, axis=0) == pytest.approx([300.0, 300.0, 300.0])  # scaled mm → m → mm
    # a mesh is its surface (fcl's BVH of triangles): the lid crosses the block's top face
    lid = _with_box(cfg, "lid", (600.0, 0.0, 650.0), (60.0, 60.0, 40.0))
    clash = _at(lid, [0.0, 0.0])
    assert clash is not None and {clash.a, clash.b} == {"link A2 (l2's mesh)", "obstacle 'lid'"}
    assert _at(lid, [0.0, -90.0]) is None
    # 20 mm above the block's top face (z 150 mm over the axis): clear by the mesh, its distance fcl's
    report = check_path(_with_box(cfg, "lid", (600.0, 0.0, 500.0 + 150.0 + 3.0 + 20.0), (60.0, 60.0, 6.0)),
                        [(np.zeros(2), "step 1: approach", -1)])
    assert report.clash is None


def test_a_dae_mesh_by_a_path_relative_to_the_urdf_is_read_in_metres(tmp_path):
    import trimesh

    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=(0.3, 0.2, 0.1)).export(tmp_path / "meshes" / "l2.dae")  # in metres, as URDF
    path = tmp_path / "arm.urdf"
    path.write_text(URDF.format(link2='<geometry><mesh filename="meshes/l2.dae"/></geometry>'), encoding="utf-8")
    [geo] = [g for g in urdf_link_geometry(path) if g.kind == "mesh"]
    assert geo.missing is None and len(geo.faces) == 12
    assert np.ptp(geo.vertices, axis=0) == pytest.approx([300.0, 200.0, 100.0])


def test_a_missing_mesh_is_refused_with_its_exit_code_and_hint(tmp_path):
    cfg = load_config(_cell(tmp_path / "urdf", MESH))  # the import goes on: only the check needs the mesh
    [geo] = [g for g in cfg.robot_collision.geometry if g.kind == "mesh"]
    assert geo.missing is not None and "package://arm_description/meshes/l2.stl" in geo.missing
    with pytest.raises(ConfigError) as err:
        check_path(cfg, [(np.zeros(2), "step 1: approach", -1)])
    assert err.value.exit_code == 2
    text = str(err.value)
    assert "'l2'" in text and "package://arm_description/meshes/l2.stl" in text
    assert "not found" in text and "delete that <collision>" in text and "docs/collision.md" in text


def test_the_geometry_rides_on_the_station_frames_of_its_links(tmp_path):
    """Each shape's frame in the station's: the URDF's own chain of origins at the joints' zero."""
    path = tmp_path / "arm.urdf"
    path.write_text(URDF.format(link2=LINK2), encoding="utf-8")
    geo = urdf_link_geometry(path)
    assert [(g.urdf_link, g.link, g.frame, g.kind) for g in geo] == [
        ("base", "R", -1, "box"), ("l1", "A1", 1, "box"), ("l2", "A2", 2, "cylinder")]
    assert geo[0].local[:3, 3] == pytest.approx([0.0, 0.0, 200.0])
    assert geo[1].local[:3, 3] == pytest.approx([200.0, 0.0, 0.0])
    assert geo[2].local[:3, 3] == pytest.approx([150.0, 0.0, 0.0])


@pytest.mark.parametrize("bad, said", [
    ('<geometry><box size="0.1 0.1"/></geometry>', "must be 3 finite numbers"),
    ('<geometry><sphere radius="-0.1"/></geometry>', "must be > 0"),
    ('<geometry><capsule radius="0.1" length="0.2"/></geometry>', "one <geometry> with one of"),
    ('<geometry><cone radius="0.1"/></geometry>', "is not a URDF geometry"),
])
def test_a_bad_collision_element_is_refused_naming_the_link(tmp_path, bad, said):
    path = tmp_path / "arm.urdf"
    path.write_text(URDF.format(link2=bad), encoding="utf-8")
    if "capsule" in bad:  # URDF has no capsule: one child, but not a geometry the station reads
        said = "is not a URDF geometry"
    with pytest.raises(ConfigError, match=said) as err:
        urdf_link_geometry(path)
    assert "link 'l2'" in str(err.value) and err.value.exit_code == 2


# --- a six-axis URDF through `station plan` ---------------------------------------------------------

#: the PUMA 560 example's upper arm and forearm as cylinders in its exported URDF's link frames
#: (link_A2: the upper arm 431.8 mm along x, 149.09 mm off along z; link_A3: the forearm along y)
UPPER_ARM = ('<collision><origin xyz="0.2159 0 0.149" rpy="0 1.5707963267948966 0"/>'
             '<geometry><cylinder radius="0.06" length="0.4318"/></geometry></collision>')
FOREARM = ('<collision><origin xyz="0.02032 0.2165 0" rpy="1.5707963267948966 0 0"/>'
           '<geometry><cylinder radius="0.05" length="0.433"/></geometry></collision>')


def _puma_urdf_cell(folder: Path, links: dict[str, str]) -> Path:
    """The puma560 example's cell with its robot exported to URDF, ``links`` giving link elements' insides."""
    from station.io.export.model_files import export_model
    from station.io.robot.files import load_robot

    folder.mkdir(parents=True, exist_ok=True)
    for name in ("head.toml", "body.csv"):
        shutil.copy(EXAMPLES / "puma560" / name, folder / name)
    text = export_model(load_robot(str(EXAMPLES / "puma560" / "puma560.mdh.csv")), "urdf", setup=False).text
    for link, inside in links.items():
        assert f'<link name="{link}"/>' in text
        text = text.replace(f'<link name="{link}"/>', f'<link name="{link}">{inside}</link>')
    (folder / "puma.urdf").write_text(text, encoding="utf-8")
    cell = (EXAMPLES / "puma560" / "cell.toml").read_text(encoding="utf-8")
    (folder / "cell.toml").write_text(cell.replace('model = "puma560.mdh.csv"', 'model = "puma.urdf"'), encoding="utf-8")
    return folder / "cell.toml"


def _plan(capsys, cell: Path) -> tuple[int, str, str]:
    from station.ui.cli.main import main

    rc = main(["plan", str(cell), "--json"])
    out, err = capsys.readouterr()
    return rc, out, err


def test_station_plan_checks_a_six_axis_urdf_with_its_cylinders(capsys, tmp_path):
    import json

    cell = _puma_urdf_cell(tmp_path, {"link_A2": UPPER_ARM, "link_A3": FOREARM})
    shapes, _ = cell_shapes(load_config(cell))
    assert {s.name for s in shapes.moving if s.kind == "cylinder"} == {
        "link A2 (link_A2's cylinder)", "link A3 (link_A3's cylinder)"}
    rc, out, _ = _plan(capsys, cell)
    assert rc == 0
    report = json.loads(out)["collision"]
    assert report["clash"] is None and report["poses"] > 1000


def test_station_plan_refuses_a_urdf_whose_mesh_is_missing(capsys, tmp_path):
    mesh = '<collision><geometry><mesh filename="package://puma_description/meshes/upper_arm.stl"/></geometry></collision>'
    rc, out, err = _plan(capsys, _puma_urdf_cell(tmp_path, {"link_A2": mesh}))
    assert rc == 2
    text = out + err
    assert "Traceback" not in text
    assert "link 'link_A2'" in text and "package://puma_description/meshes/upper_arm.stl" in text
    assert "the mesh file is not found" in text and "delete that <collision> element" in text


def test_station_plan_draws_a_urdf_whose_arms_are_meshes(capsys, tmp_path):
    """The picture of the cell (issue 40) draws a mesh link and measures its least clearance with it
    (fcl's BVH of the triangles, as the check uses), not only the primitives."""
    import json

    import trimesh

    from station.ui.cli.main import main

    meshes = tmp_path / "cell" / "puma_description" / "meshes"
    meshes.mkdir(parents=True)
    trimesh.creation.cylinder(radius=0.06, height=0.4318, sections=32).export(meshes / "upper_arm.stl")
    upper = UPPER_ARM.replace('<cylinder radius="0.06" length="0.4318"/>',
                              '<mesh filename="package://puma_description/meshes/upper_arm.stl"/>')
    cell = _puma_urdf_cell(tmp_path / "cell", {"link_A2": upper, "link_A3": FOREARM})
    assert any(s.kind == "mesh" for s in cell_shapes(load_config(cell))[0].moving)
    out_dir = tmp_path / "out"
    rc = main(["plan", str(cell), "--out", str(out_dir), "--json"])
    out, err = capsys.readouterr()
    assert rc == 0, err[-2000:]
    assert json.loads(out)["picture"]["svg"] == str(out_dir / "cell.svg")
    assert (out_dir / "cell.svg").stat().st_size > 10_000
