"""The moves the plan does not hold, checked before motion (issue 40, station/cell/plan/first_moves.py):
the first move from where the robot stands and the search touches of locating the body go through
the plan's collision check, and one that collides is refused before anything moves, with the pair
and the distance named, in 'plan' and in 'calibrate'."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.config.sections import ObstacleConfig
from station.cell.pipeline.premotion import check_first_motion
from station.cell.plan import first_moves
from station.cell.plan.collision import check_path
from station.cell.plan.collision_shapes import head_shapes
from station.cell.plan.first_moves import (
    check_first_move,
    check_locating_moves,
    face_directions,
    first_move_path,
    locate_steps,
    search_offsets,
    touch_poses,
)
from station.cell.plan.measurement_plan import build_plan
from station.core.kinematics.forward import forward
from station.errors import ConfigError, UnreachableError

pytest.importorskip("fcl")

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def scara():
    cfg = load_config(EXAMPLES / "scara600" / "cell.toml")
    plan = build_plan(cfg)
    return cfg, plan, plan.run_steps(cfg.plan.verification_cycles, False)


def _box(name: str, centre: np.ndarray, edge: float) -> ObstacleConfig:
    pose = np.eye(4)
    pose[:3, 3] = centre
    return ObstacleConfig(name, "box", "base", pose, (edge, edge, edge))


def _mount(cfg, q: np.ndarray) -> np.ndarray:
    """Where the head's mount (its capsule's centre, between the flange and the head frame) is at
    ``q``, in the robot base frame [mm]."""
    mount = next(s for s in head_shapes(cfg) if s.name == "head mount")
    return (forward(cfg.model, np.asarray(q)[None], setup=False)[0] @ mount.local)[:3, 3]


def test_the_first_move_is_what_the_runner_commands(scara):
    """From the parked joints: the quill up to the travel height, then the first step's touch as
    the runner makes it (approach, above the point, touch, retract)."""
    cfg, _plan, steps = scara
    here = cfg.conformance.park_joints
    poses = first_move_path(cfg, here, steps[0])
    assert np.allclose(poses[0][0], here)
    assert [p[1].split(": ")[-1] for p in poses[-4:]] == ["approach", "above the point", "touch", "retract"]
    assert np.allclose(poses[-2][0], steps[0].q)
    assert poses[1][1] == "the first move: retract to travel height" and poses[1][0][2] > here[2]
    report = check_first_move(cfg, here, steps[0], "[conformance] park_joints")
    assert report.clash is None and report.poses == len(poses)


#: where the robot stands in the tests below: parked with its quill low, 145 mm under the travel height
LOW = -150.0


def _lamp(cfg, here: np.ndarray) -> ObstacleConfig:
    """A box over the head of a robot standing at ``here``, between its mount and its arm (over 20 mm
    from each): the quill's retract, straight up (a SCARA's first move has no way around), runs into it."""
    return _box("lamp", _mount(cfg, here) + np.array([0.0, 0.0, 100.0]), 20.0)


def test_a_first_move_into_an_obstacle_is_refused_naming_the_pair(scara):
    """The robot parked low under a lamp: where it stands is clear, its first move is not. Refused
    (exit 4, nothing commanded) with the pair, the move and the distance; without the lamp, clear."""
    cfg, _plan, steps = scara
    here = cfg.conformance.park_joints.copy()
    here[2] = LOW
    assert check_first_move(cfg, here, steps[0], "[conformance] park_joints").clash is None
    lit = dataclasses.replace(cfg, obstacles=(_lamp(cfg, here),))
    assert check_path(lit, first_move_path(lit, here, steps[0])[:1]).clash is None  # where it stands: clear
    with pytest.raises(UnreachableError) as err:
        check_first_move(lit, here, steps[0], "[conformance] park_joints")
    text = str(err.value)
    assert err.value.exit_code == 4
    assert "the first move from [conformance] park_joints (joints 0.0 deg, 90.0 deg, -150.0 mm" in text
    assert "obstacle 'lamp'" in text and "mm of each other" in text and "the first move" in text
    assert "nothing was moved" in text


def test_a_robot_left_at_a_touch_moves_off_it_by_that_touchs_rules(scara):
    """A run stopped at a safe point leaves the head on its last touch (its tips on the cube): the
    first move of the resumed run retracts from it as that touch's retract, and is clear."""
    cfg, _plan, steps = scara
    st = steps[5]
    poses = first_move_path(cfg, st.q, steps[6])
    assert poses[0][1] == f"the first move from the touch of {st.point_id}: touch" and poses[0][2] == st.point
    assert check_first_move(cfg, st.q, steps[6], "where the robot stands").clash is None
    untouched = [(q, label.replace(": touch", ": standing"), -1) for q, label, _ in poses[:1]]
    assert check_path(cfg, untouched).clash is not None  # the same pose held to the full margin: its tips clash


def test_calibrate_checks_the_first_move_from_the_joints_read(scara):
    """The first step not yet measured is the target (a resumed run's next one)."""
    cfg, _plan, steps = scara
    here = cfg.conformance.park_joints
    assert check_first_motion(cfg, here, steps, set()).poses == len(first_move_path(cfg, here, steps[0]))
    assert check_first_motion(cfg, here, steps, {0, 1}).poses == len(first_move_path(cfg, here, steps[2]))
    assert check_first_motion(cfg, here, steps, {st.index for st in steps}) is None


def test_the_search_touches_cover_the_bounded_box_of_offsets(scara):
    cfg, _plan, steps = scara
    off = search_offsets(cfg)
    bound = float(np.abs(off).max())  # every face at minus, none or plus it: the box's 26 corners and sides
    assert len(off) == 26 and set(np.round(off, 9).ravel()) == {-round(bound, 9), 0.0, round(bound, 9)}
    assert 0.0 < bound <= min(cfg.plan.setup_uncertainty_mm, cfg.plan.clearance_mm)
    assert len(locate_steps(cfg, steps)) == first_moves.N_LOCATE and locate_steps(cfg, steps)[0] == steps[0]
    report = check_locating_moves(cfg, build_plan(cfg))
    assert report is not None and report.clash is None
    # each search touch: from the planned retract, then its own four poses, for each locating point
    assert report.poses == 5 * len(off)
    none = dataclasses.replace(cfg, plan=dataclasses.replace(cfg.plan, locate_steps=0))
    assert len(search_offsets(none)) == 0 and check_locating_moves(none, build_plan(none)) is None


def test_a_search_touch_that_would_hit_an_obstacle_the_touch_clears_is_refused(scara):
    """A box behind the head at the first locating point, as near as the planned touch clears it
    by the margin: the search, which backs the head off along a face's normal by its bound, would
    hit it; 'plan' refuses before anything moves, naming the pair and the search touch."""
    cfg, _plan, steps = scara
    st = steps[0]
    T = forward(cfg.model, st.q[None], setup=False)[0]
    back = -(T[:3, :3] @ face_directions(cfg)[1])  # away from the x face
    bound = float(np.abs(search_offsets(cfg)).max())
    nominal = touch_poses(cfg, st.q, st, [f"step 1 ({st.label})"])
    for d in np.arange(20.0, 200.0, 1.0):  # the nearest place the planned touch clears
        crate = _box("crate", T[:3, 3] + back * d, 6.0)
        near = dataclasses.replace(cfg, obstacles=(crate,))
        r = check_path(near, nominal)
        if r.clash is None:
            break
    assert r.clash is None and r.closest is not None and "crate" in r.closest.a + r.closest.b
    assert r.closest.clearance_mm < cfg.plan.collision_margin_mm + 1.0 < bound
    with pytest.raises(ConfigError) as err:
        check_locating_moves(near, build_plan(cfg))
    text = str(err.value)
    assert "a search touch of locating the body collides" in text and "obstacle 'crate'" in text
    assert f"search touch at {st.point_id}" in text and "mm of each other" in text and "nothing was moved" in text


def _low_cell_with_a_lamp(tmp_path: Path) -> Path:
    """examples/scara600 parked low under a lamp (the cell's files copied beside it)."""
    cfg = load_config(EXAMPLES / "scara600" / "cell.toml")
    here = cfg.conformance.park_joints.copy()
    here[2] = LOW
    lamp = _lamp(cfg, here)
    for name in ("robot.toml", "head.toml", "body.csv"):
        shutil.copy(EXAMPLES / "scara600" / name, tmp_path / name)
    text = (EXAMPLES / "scara600" / "cell.toml").read_text()
    parked = "park_joints = [0.0, 90.0, -6.0, 0.0]"
    assert parked in text
    x, y, z = lamp.pose[:3, 3]
    text = text.replace(parked, f"park_joints = [0.0, 90.0, {LOW}, 0.0]")
    text += (f'\n[[obstacle]]\nname = "lamp"\nshape = "box"\nframe = "base"\nsize_mm = [20.0, 20.0, 20.0]\n'
             f'pose = [{x:.3f}, {y:.3f}, {z:.3f}, 0.0, 0.0, 0.0]\n')
    path = tmp_path / "cell.toml"
    path.write_text(text)
    return path


def test_plan_and_calibrate_refuse_a_first_move_from_the_park_that_collides(tmp_path, capsys):
    """'station plan' checks the first move from [conformance] park_joints, and 'calibrate' (on the
    simulated cell, whose robot starts there) refuses it before anything moves: exit 4, the pair named."""
    from station.ui.cli.main import main

    path = _low_cell_with_a_lamp(tmp_path)
    for args in (["plan", str(path), "--json"],
                 ["calibrate", "--simulated", str(path), "--db", str(tmp_path / "runs.sqlite"), "--json"]):
        code = main(args)
        out = capsys.readouterr().out
        assert code == 4, out
        doc = json.loads(out.strip().splitlines()[-1])
        message = doc["failure"]["message"]
        assert "the first move from [conformance] park_joints" in message and "obstacle 'lamp'" in message
        assert "mm of each other" in message and "nothing was moved" in message
