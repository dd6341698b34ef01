"""Identifiability of the SR 800 parameters: the chapter's reference counts (brief §3), the
minimal-set choice and its preferences, dependencies, and zero-effect columns."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.identification.identifiability import analyze
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import random_pairs, synthetic_set
from station.io.robot.files import load_robot

SR800 = load_robot("sr800")


def joints(planar=False, n=30, seed=1):
    return spread_joints(SR800, n, np.random.default_rng(seed), planar=planar)


def data(kind, planar=False, n=30, seed=1, n_pairs=200):
    q = joints(planar, n, seed)
    pairs = random_pairs(n, n_pairs, np.random.default_rng(seed + 100)) if kind == "distance" else None
    return synthetic_set(SR800, kind, q, SR800.nominal, pairs=pairs)


def run(kind, planar=False, seed=1, **kw):
    kw.setdefault("prefer", SR800.prefer)
    return analyze(SR800, data(kind, planar, seed=seed), **kw)


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("kind,planar,rank", [
    ("pose", False, 20),
    ("pose", True, 18),
    ("position", False, 17),
    ("distance", False, 11),
    ("distance", True, 5),
])
def test_reference_ranks(kind, planar, rank, seed):
    a = run(kind, planar, seed=seed)
    assert a.rank == rank
    assert len(a.chosen) == rank
    assert a.chosen_singular_values.shape == (rank,)
    # the chosen set is itself full rank and well away from the round-off floor
    assert a.chosen_singular_values[-1] / a.chosen_singular_values[0] > 1e-6
    assert np.isfinite(a.condition) and a.condition >= 1.0
    # singular values beyond the rank are round-off
    s = a.singular_values
    if len(s) > rank:
        assert s[rank] < 1e-9 * s[0]


def test_pose_rank_equals_minimal_model():
    assert run("pose").rank == SR800.minimal_param_count == 20


def test_planar_distance_set_is_the_chapters():
    """Two arm lengths, offset of axis 2, head offset x and y (brief §3 table)."""
    a = run("distance", planar=True)
    assert set(a.chosen) == {"A2.x", "A3.x", "A2.yaw", "K.x", "K.y"}


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_distance_nine_parameter_sets(seed):
    full = run("distance", seed=seed)
    assert full.rank == 11
    no_a3 = run("distance", seed=seed, exclude=("A3.roll", "A3.pitch"))
    no_a4 = run("distance", seed=seed, exclude=("A4.roll", "A4.pitch"))
    assert no_a3.rank == 9 and no_a4.rank == 9
    assert not {"A3.roll", "A3.pitch"} & set(no_a3.chosen)
    assert not {"A4.roll", "A4.pitch"} & set(no_a4.chosen)
    assert {"A3.roll", "A3.pitch"} <= set(no_a4.chosen)
    # Without the axis-4 tilts the 9-set is well conditioned (the tilt of axis 4 under the
    # 128 mm probe mimics an arm-length change); excluding A3's tilts does not achieve that.
    assert no_a4.chosen_condition * 10 <= full.chosen_condition
    assert no_a4.chosen_condition < 100
    assert no_a3.chosen_condition > 5 * no_a4.chosen_condition
    assert set(no_a4.held) == {"A4.roll", "A4.pitch"}


def test_prefer_is_honoured():
    d = data("pose")
    default = analyze(SR800, d, prefer=SR800.prefer)
    assert "R.x" in default.chosen and "A1.x" not in default.chosen
    a = analyze(SR800, d, prefer=("A2.y", *SR800.prefer))
    assert a.rank == 20
    assert "A2.y" in a.chosen and "A2.yaw" not in a.chosen  # A2.y ≡ 325·A2.yaw + a turn about axis 1
    # every identifiable preferred parameter of the robot file's list is chosen unless it is a
    # combination of the set-up's and those before it: K.z ≡ R.z on a SCARA, so the set-up keeps it
    assert {"K.x", "K.y", "K.roll", "K.pitch", "K.yaw", "A2.x", "A3.x"} <= set(default.chosen)
    assert "K.z" not in default.chosen


@pytest.mark.parametrize("kind,planar", [("pose", False), ("pose", True), ("position", False)])
def test_setup_keeps_what_the_body_cannot_tell_from_it(kind, planar):
    """The set-up R is chosen in full before any preference (issue 36): the robot's base-frame
    parameters (axis 1's height, origin, tilt and zero) merge into R, never R into the robot's,
    with the robot file's list, none, or one that asks for the robot's base parameters."""
    d = data(kind, planar)
    for prefer in (SR800.prefer, (), ("A1.x", "A1.z", "A1.yaw", "K.z")):
        a = analyze(SR800, d, prefer=prefer)
        assert set(SR800.param_names[:6]) <= set(a.chosen)
        assert not {n for n in a.chosen if n.startswith("A1.")}
        deps = {dep.name: dict(dep.merges_with) for dep in a.dependencies}
        assert deps["A1.z"] == pytest.approx({"R.z": 1.0}, abs=1e-6)
        assert deps["A1.yaw"]["R.yaw"] == pytest.approx(1.0, abs=1e-6)
    # holding R (a set-up measured otherwise) hands those directions to the robot
    held = analyze(SR800, d, prefer=SR800.prefer, fix=SR800.param_names[:6])
    assert held.rank == a.rank and {"A1.x", "A1.y"} <= set(held.chosen)


def test_preferred_but_unidentifiable_is_not_chosen():
    a = run("distance", prefer=("R.x", "K.roll", "A1.yaw"))
    assert not {"R.x", "K.roll", "A1.yaw"} & set(a.chosen)
    assert a.rank == 11


def test_fixed_and_excluded_never_chosen():
    d = data("pose")
    held = ("R.x", "K.z", "A2.yaw")
    a = analyze(SR800, d, prefer=("R.x", *SR800.prefer), fix=held[:2], exclude=held[2:])
    assert not set(held) & set(a.chosen)
    assert set(a.held) == set(held)
    assert a.rank == 20  # merged parameters take their place (A1.x ≡ R.x, R.z ≡ K.z, ...)
    assert {"A1.x"} <= set(a.chosen)
    # holding a parameter nothing else can stand in for loses rank, and says so
    k = analyze(SR800, d, prefer=SR800.prefer, fix=("K.x", "K.y"))
    assert k.rank < 20 and not {"K.x", "K.y"} & set(k.chosen)
    # preferring a held parameter does not sneak it in
    b = analyze(SR800, d, prefer=("K.z",), fix=("K.z",))
    assert "K.z" not in b.chosen


def test_dependencies_pose():
    a = run("pose")
    deps = {d.name: dict(d.merges_with) for d in a.dependencies}
    assert set(deps) | set(a.chosen) == set(SR800.param_names)
    assert not set(deps) & set(a.chosen)
    assert deps["A1.x"] == pytest.approx({"R.x": 1.0}, abs=1e-6)
    assert deps["A1.y"] == pytest.approx({"R.y": 1.0}, abs=1e-6)
    assert deps["A1.z"] == pytest.approx({"R.z": 1.0}, abs=1e-6)
    # A1.pitch tilts the whole robot about the base 800 mm below axis 1's origin
    assert deps["A1.pitch"] == pytest.approx({"R.x": -800.0, "R.pitch": 1.0}, abs=1e-6)
    desc = [d.describe() for d in a.dependencies]
    assert any(s.startswith("A1.x ≡ +1·R.x") for s in desc)
    assert a.zero_effect == ()


def test_dependency_coefficients_are_true_combinations():
    """J[:, dep] == Σ coef · J[:, chosen] — checked on fresh poses, not the analysed ones."""
    from station.core.identification.identifiability import weighted_jacobian

    a = run("pose")
    J = weighted_jacobian(SR800, data("pose", seed=7))
    for d in a.dependencies:
        if not d.merges_with:
            continue
        combo = sum(c * J[:, SR800.param_index(n)] for n, c in d.merges_with)
        col = J[:, SR800.param_index(d.name)]
        assert np.linalg.norm(combo - col) <= 1e-5 * np.linalg.norm(col), d.describe()


def test_zero_effect_columns_detected_before_scaling():
    a = run("distance")
    for name in ("K.roll", "K.pitch", "K.yaw", "R.x", "R.yaw", "A1.x", "A1.yaw", "K.z", "A2.z"):
        assert name in a.zero_effect
        assert name not in a.candidates and name not in a.chosen
    deps = {d.name: d for d in a.dependencies}
    assert deps["K.roll"].merges_with == ()
    assert deps["K.roll"].describe() == "K.roll: no effect on these measurements"
    # scaling zero columns would have produced fake rank: rank must still be 11
    assert a.rank == 11
    pos = run("position")
    assert set(pos.zero_effect) == {"K.roll", "K.pitch", "K.yaw"}


def test_to_dict_json_ready():
    import json

    d = run("pose").to_dict()
    back = json.loads(json.dumps(d))
    assert back["rank"] == 20 and back["n_parameters"] == 36 and len(back["chosen"]) == 20


def test_unknown_names_rejected():
    from station.errors import ConfigError

    with pytest.raises(ConfigError, match="unknown parameter 'K.q'"):
        run("pose", prefer=("K.q",))
    with pytest.raises(ConfigError, match="unknown parameter"):
        run("pose", exclude=("A5.x",))
