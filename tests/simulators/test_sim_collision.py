"""The simulated controller's own collision check (issue 40, simulators/collision_check.py): a
colliding motion is refused over the real transport with error COLLISION and the driver's typed
error, a clear one is carried out; the plan of today's main collides in the independent check on
the two example cells with obstacles; and those cells rehearse to SUCCESS with no collision once
the station's plans carry via poses (branch h40a)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from drivers.controller import ModbusController
from drivers.controller_errors import MotionCollision, error_for
from drivers.controller_map import Command, ErrorCode
from simulators.arm_kinematics import ArmKinematics
from simulators.collision_check import CellCollision
from simulators.controller_server import SimulatedController
from simulators.truth_kinematics import inverse, pose_matrix
from station.cell.config.cell_config import load_config, parse_text
from station.cell.pipeline.outcomes import classify
from station.errors import Outcome

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SCARA = EXAMPLES / "scara600_column" / "cell.toml"
PUMA = EXAMPLES / "puma560_obstacles" / "cell.toml"


@pytest.fixture(scope="module")
def scara():
    return load_config(SCARA)


def _over_the_column(cfg) -> np.ndarray:
    """Joints that put the SCARA's head frame 150 mm over the plate, right above the column's
    axis (the simulator's own inverse kinematics, elbow +1)."""
    (column,) = cfg.obstacles
    base_from_body = inverse(pose_matrix(np.asarray(cfg.model.nominal[:6])))
    target = np.eye(4)
    target[:3, 3] = (base_from_body @ np.array([*column.pose[:2, 3], 150.0, 1.0]))[:3]
    kin = ArmKinematics([t.joint for t in cfg.model.transforms], cfg.model.nominal)
    return kin.scara_inverse(target, 1)


def _plan(cfg) -> list:
    """(joints, what, point) of every pose the station commands for ``cfg``, in order, as planned
    on main today."""
    from station.cell.plan.measurement_plan import build_plan
    from station.cell.plan.run_path import plan_path

    return plan_path(cfg, build_plan(cfg))


def _commanded(cfg) -> list[np.ndarray]:
    return [q for q, _, _ in _plan(cfg)]


def test_the_check_finds_the_column_under_the_head_and_not_beside_it(scara):
    cc = CellCollision.from_config(scara)
    q = _over_the_column(scara)
    hit = cc.check_joints(q[None])
    assert hit is not None and hit.b == "obstacle 'column'", hit
    assert hit.depth_mm > 10.0  # the head stands in it, not beside it
    aside = q + np.array([0.5, 0.0, 0.0, 0.0])  # axis 1 turned on by 0.5 rad: the head ~0.2 m away
    assert cc.check_joints(aside[None]) is None
    # the path between two clear poses either side of the column passes through it
    before = q - np.array([0.5, 0.0, 0.0, 0.0])
    assert cc.check_joints(before[None]) is None
    through = cc.check_move(before, aside)
    assert through is not None and through.b == "obstacle 'column'" and 0.0 < through.fraction < 1.0


def test_a_colliding_motion_is_refused_over_modbus_and_a_clear_one_runs(scara):
    """Over TCP: the driver's joint move whose path crosses the column gets COLLISION (the typed
    MotionCollision, exit 4 by the station's classification), nothing moves; a clear move runs."""
    q = _over_the_column(scara)
    before, aside = q - [0.5, 0.0, 0.0, 0.0], q + [0.5, 0.0, 0.0, 0.0]
    with SimulatedController(model=scara.model, soft_limits=scara.soft_limits,
                             collision=CellCollision.from_config(scara)) as sim:
        ctl = ModbusController("127.0.0.1", sim.port, heartbeat_period=0.05)
        ctl.connect()
        try:
            ctl.move_joints(before, speed=0.5).wait(5.0)  # clear: carried out
            np.testing.assert_allclose(ctl.read_joints(), before, atol=1e-5)
            with pytest.raises(MotionCollision, match="collision check") as ei:
                ctl.move_joints(aside, speed=0.5).wait(5.0)  # its path crosses the column
            assert ei.value.code == ErrorCode.COLLISION == 18
            st = ctl.status()
            assert st.error_code == 18 and st.ready and not st.moving  # refused, not latched
            np.testing.assert_allclose(ctl.read_joints(), before, atol=1e-5)  # nothing moved
            (seq, hit), = sim.collisions
            assert seq == ei.value.seq and hit.b == "obstacle 'column'"
            around = before - [0.4, 0.0, 0.0, 0.0]  # away from the column: carried out
            ctl.move_joints(around, speed=0.5).wait(5.0)
            np.testing.assert_allclose(ctl.read_joints(), around, atol=1e-5)
            assert len(sim.collisions) == 1 and sim.collision is not None and sim.collision.moves_checked == 3
        finally:
            ctl.close()
    assert classify(ei.value) is Outcome.UNREACHABLE


def test_the_driver_types_the_collision_code():
    class St:
        error_code, error_joint, error_bound = int(ErrorCode.COLLISION), 0, 0

    err = error_for(St(), 7, Command.MOVE_CARTESIAN, None, None)
    assert isinstance(err, MotionCollision) and err.seq == 7 and "nothing moved" in str(err)


def test_the_switch_is_on_by_default_and_off_only_when_the_file_says_so(scara):
    """A cell with its own files is checked unless its [simulation] says false (issue 40: a
    planning slip fails the rehearsal); the key absent is None, not true, so that the built-in cell
    (no files to check against) is not refused for a key nobody wrote."""
    from simulators.from_config import simulate_config

    plain = load_config(EXAMPLES / "scara600" / "cell.toml")
    assert plain.simulation.collision_check is None
    assert scara.simulation.collision_check is True
    with simulate_config(plain, seed=1, source=EXAMPLES / "scara600" / "cell.toml") as default:
        assert isinstance(default.servers.controller_server.collision, CellCollision)
    text = SCARA.read_text().replace("collision_check = true", "collision_check = false")
    with simulate_config(parse_text(text, str(SCARA)), seed=1, source=SCARA) as off:
        assert off.servers.controller_server.collision is None


def test_the_builtin_cell_refuses_the_switch(tmp_path, capsys):
    """The built-in cell has no files of its own to check against: a typed refusal, exit 2."""
    from station.ui.cli.main import main

    only = tmp_path / "sim.toml"
    only.write_text("[simulation]\ncollision_check = true\n")
    code = main(["calibrate", "--simulated", str(only), "--db", str(tmp_path / "r.sqlite"), "--json"])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 2 and summary["outcome"] == "CONFIG_ERROR" and "collision_check" in summary["failure"]["message"]


def test_a_robot_that_would_start_inside_something_is_refused():
    """At q = 0 the PUMA's forearm hangs down through where a table under the body stands (an
    [[obstacle]]): without [conformance] park_joints the simulated controller could check no motion
    from there, and says so."""
    from simulators.from_config import simulate_config
    from station.errors import ConfigError

    table = ('\n[[obstacle]]\nname = "table"\nshape = "box"\nframe = "body"\n'
             'pose = [0.0, 0.0, -40.0, 0.0, 0.0, 0.0]\nsize_mm = [1200.0, 1200.0, 60.0]\n')
    text = PUMA.read_text()
    unparked = text[:text.index("[conformance]")] + text[text.index("[identification]"):]
    with pytest.raises(ConfigError, match=r"start where link .* obstacle 'table' overlap .*park_joints"):
        simulate_config(parse_text(unparked + table, str(PUMA)), seed=1, source=PUMA)


def test_the_plungers_may_press_on_a_cube_the_housings_may_not(scara):
    """At a planned touch the probes' plungers press on the cube (their job: no collision); the
    quill 12 mm lower drives the probes' housings into it (more than the 8 mm stroke allows)."""
    cc = CellCollision.from_config(scara)
    touch = next(q for q, label, _ in _plan(scara) if label.endswith("touch"))
    assert cc.check_joints(touch[None]) is None
    deeper = touch - np.array([0.0, 0.0, 12.0, 0.0])  # the quill (mm) further down
    hit = cc.check_joints(deeper[None])
    assert hit is not None and "plunger" not in hit.a and hit.b.startswith(("cube", "the pillar")), hit


def test_skipping_the_far_stretches_finds_what_every_sample_finds():
    """check_move looks at every COARSE-th sample first and skips stretches that cannot reach
    anything: on 30 random moves between the PUMA plan's poses (seeded) it finds exactly the first
    collision the check of every sample finds, or none where that finds none."""
    cfg = load_config(PUMA)
    poses = _commanded(cfg)
    cc = CellCollision.from_config(cfg)
    rng = np.random.default_rng(40)
    verdicts = []
    for a, b in rng.integers(0, len(poses), (30, 2)):
        full = cc.check_joints(*cc.samples(poses[a], poses[b]))
        assert cc.check_move(poses[a], poses[b]) == full
        verdicts.append(full is None)
    assert 0 < sum(verdicts) < len(verdicts)  # both kinds of move were tried


def test_a_plan_the_stations_check_clears_is_not_refused():
    """examples/scara600: the station's own check finds today's plan clear (docs/collision.md,
    "Figures"); the simulator's shapes lie inside the station's, so it refuses none of its moves."""
    cfg = load_config(EXAMPLES / "scara600" / "cell.toml")
    poses = _commanded(cfg)
    cc = CellCollision.from_config(cfg)
    refused = [i for i in range(1, len(poses)) if cc.check_move(poses[i - 1], poses[i]) is not None]
    assert refused == [] and cc.moves_checked == len(poses) - 1


# ------------------------------------------------------------------ today's plan collides



@pytest.mark.parametrize("cell", [PUMA, SCARA], ids=["puma560_obstacles", "scara600_column"])
def test_the_plan_without_its_vias_collides_in_the_simulators_check(cell, monkeypatch):
    """Every measuring pose of the plan is clear of everything, but without its via poses (the plan
    before issue 40: direct joint moves between the measurements) the joint-space paths run into the
    cell's obstacles: the check the simulated controller runs refuses it. With the vias, it clears
    every move (the station's own check and the simulator's agree)."""
    import station.cell.plan.vias as vias

    cfg = load_config(cell)
    cc = CellCollision.from_config(cfg)
    planned = _commanded(cfg)
    assert all(cc.check_move(planned[i - 1], planned[i]) is None for i in range(1, len(planned)))
    monkeypatch.setattr(vias, "travel_vias", lambda *a, **k: [])  # via_memo asks vias.travel_vias per call
    poses = _commanded(cfg)
    assert len(poses) < len(planned)
    cc = CellCollision.from_config(cfg)
    assert cc.check_joints(np.array(poses)) is None  # no pose itself collides
    names = {f"obstacle {o.name!r}" for o in cfg.obstacles}
    hits = []
    for i in range(1, len(poses)):
        hit = cc.check_move(poses[i - 1], poses[i])
        if hit is not None and hit.b in names:
            hits.append((i, hit))
            if {h.b for _, h in hits} == names:
                break
    assert {h.b for _, h in hits} == names, f"obstacles hit: {[h.describe() for _, h in hits]}"
    assert all(h.depth_mm > 0.0 and 0.0 < h.fraction <= 1.0 for _, h in hits)


# ------------------------------------------------------------------ end to end (needs the via poses)

def _rehearse(cell: Path, tmp_path: Path, capsys, monkeypatch):
    """``station calibrate --simulated CELL --json``: its exit code, its JSON summary and the
    simulated controller it ran against."""
    import simulators.from_config as from_config
    from station.ui.cli.main import main

    started = []
    real = from_config.simulate_config

    def recorded(*args, **kwargs):
        started.append(real(*args, **kwargs))
        return started[-1]

    monkeypatch.setattr(from_config, "simulate_config", recorded)
    code = main(["calibrate", "--simulated", str(cell), "--db", str(tmp_path / "runs.sqlite"), "--json"])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    (rehearsal,) = started
    return code, summary, rehearsal.servers.controller_server


@pytest.mark.slow
def test_a_clear_cell_rehearses_to_success_with_the_check_on(tmp_path, capsys, monkeypatch):
    """examples/scara600 (no obstacles; the station's own check clears its plan) with the check
    switched on: every motion of the whole run is checked, none refused, the run ends SUCCESS."""
    import shutil

    for name in ("robot.toml", "head.toml", "body.csv"):
        shutil.copy(EXAMPLES / "scara600" / name, tmp_path / name)
    text = (EXAMPLES / "scara600" / "cell.toml").read_text()
    (tmp_path / "cell.toml").write_text(text.replace("[simulation]\n", "[simulation]\ncollision_check = true\n"))
    code, summary, controller = _rehearse(tmp_path / "cell.toml", tmp_path, capsys, monkeypatch)
    assert controller.collision is not None and controller.collision.moves_checked > 500
    assert controller.collisions == [], [h.describe() for _, h in controller.collisions[:3]]
    assert code == 0 and summary["outcome"] == "SUCCESS", summary.get("failure")


@pytest.mark.slow
@pytest.mark.parametrize("cell", [PUMA, SCARA], ids=["puma560_obstacles", "scara600_column"])
def test_the_example_rehearses_to_success_without_a_collision(cell, tmp_path, capsys, monkeypatch):
    code, summary, controller = _rehearse(cell, tmp_path, capsys, monkeypatch)
    assert controller.collision is not None and controller.collision.moves_checked > 100
    assert controller.collisions == [], [h.describe() for _, h in controller.collisions[:3]]
    assert code == 0 and summary["outcome"] == "SUCCESS", summary.get("failure")
