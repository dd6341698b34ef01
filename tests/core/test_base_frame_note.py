"""The words that say which directions are the set-up's and what the base frame is tied to (36)."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.identification.base_frame import BASE_FRAME_NOTE_PREFIX, base_frame_note, setup_directions
from station.core.identification.identifiability import analyze
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import random_pairs, synthetic_set
from station.io.robot.files import load_robot

SCARA = load_robot("examples/scara600/robot.toml")
ARM = load_robot("examples/puma560/puma560.mdh.csv")
A1 = ("A1.x", "A1.y", "A1.z", "A1.roll", "A1.pitch", "A1.yaw")


def data(m, kind, n=40):
    q = spread_joints(m, n, np.random.default_rng(1))
    pairs = random_pairs(n, 300, np.random.default_rng(2)) if kind == "distance" else None
    return synthetic_set(m, kind, q, m.nominal, pairs=pairs)


@pytest.mark.parametrize("m", [SCARA, ARM], ids=["scara", "six-axis"])
@pytest.mark.parametrize("kind", ["pose", "position", "distance"])
def test_the_base_parameters_are_named_with_and_without_prefer(m, kind):
    for prefer in (m.prefer, ()):
        a = analyze(m, data(m, kind), prefer=prefer)
        names = setup_directions(m, a)
        assert set(A1) <= set(names) and not set(names) & set(a.chosen)
        note = base_frame_note(m, a)
        assert note is not None and note.startswith(BASE_FRAME_NOTE_PREFIX)
        assert "the zero of joint 1" in note and "height along axis 1" in note
        assert ("Distances do not see" in note) == (kind == "distance")
    if m is SCARA and kind != "distance":  # every height along the parallel axes is the set-up's
        assert "K.z" in setup_directions(m, analyze(m, data(m, kind), prefer=m.prefer))


def test_held_setup_measures_the_base_and_says_nothing():
    a = analyze(SCARA, data(SCARA, "pose"), prefer=SCARA.prefer, fix=SCARA.param_names[:6])
    assert base_frame_note(SCARA, a) is None


def test_identify_says_it():
    res = identify(SCARA, data(SCARA, "pose"))
    assert any(n.startswith(BASE_FRAME_NOTE_PREFIX) and "A1.z" in n for n in res.notes)
