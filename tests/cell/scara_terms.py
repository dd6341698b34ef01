"""A SCARA whose gears err once per turn, identified with error terms on the same data, cheaply
(no session): the built-in simulated SCARA's configuration with ``[identification] model = "auto"``
and a 200 mm gripper (its grid given: designing one takes a while), its plan's identification poses measured on a truth with the joint errors of
``simulators.joint_errors.scara_joint_errors(1)`` (as tests/cell/test_session_terms.py does), the
geometric fit and the selection ``auto`` keeps. Shared by the tests of everything a model with
terms goes into (tools, export, report)."""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import numpy as np

GRIPPER = """
[[tool]]
name = "gripper"
tcp = [50.0, 0.0, -200.0, 0.0, 0.0, 0.0]
x_mm = [275.0, 650.0, 37.5]
y_mm = [-350.0, 350.0, 70.0]
z_mm = [150.0, 350.0, 200.0]
"""


@dataclasses.dataclass(frozen=True, eq=False)
class ScaraTerms:
    cfg: Any  # CellConfig (the gripper configured)
    truth: Any  # CellTruth with joint errors, no backlash
    steps: tuple  # the plan's run steps (one cycle, no oracle)
    geo: Any  # IdentificationResult: the geometric fit
    sel: Any  # Selection: what auto keeps
    delta: Any  # q ↦ δ(q) of the kept terms
    measured: Any  # (n, 4, 4) the identification poses' measured heads, world frame [mm]


@functools.lru_cache(maxsize=1)
def scara_terms() -> ScaraTerms:
    from simulators.cell import CellTruth, SimulatedCell
    from simulators.joint_errors import scara_joint_errors
    from simulators.reference_cell import cell_config_text
    from station.cell.config.cell_config import parse_text
    from station.cell.pipeline.terms import terms_delta
    from station.cell.plan.measurement_plan import build_plan
    from station.cell.plan.steps import StepKind
    from station.core.identification.identify import identify
    from station.core.measurement.measurements import MeasurementSet
    from station.core.terms.error_model import TermSpec
    from station.core.terms.selection import select_model

    class Servers:  # what the configuration's text takes of the started servers
        def __init__(self) -> None:
            self.cell = SimulatedCell(seed=1)
            self.probe_port = "socket://127.0.0.1:1"
            self.controller_host, self.controller_port = "127.0.0.1", 1502

    text = cell_config_text(Servers(), 1).replace("[identification]\n", '[identification]\nmodel = "auto"\n', 1)
    cfg = parse_text(text + GRIPPER, "<scara>")
    truth = dataclasses.replace(CellTruth.generate(seed=1), joint_errors=scara_joint_errors(1))
    truth = dataclasses.replace(truth, backlash=np.zeros_like(truth.backlash))  # the joint errors alone
    steps = build_plan(cfg).run_steps(1, False)
    q = np.array([st.q for st in steps if st.kind is StepKind.IDENTIFICATION])
    rng = np.random.default_rng(5)
    stands = q + truth.joint_delta(q) + rng.normal(0.0, 1.0, q.shape) * truth.repeatability
    measured = truth.head_pose(stands)
    data = MeasurementSet("pose", q, measured, cfg.identification.pose_sigma())
    geo = identify(cfg.model, data)
    sel = select_model(cfg.model, data, spec=TermSpec(), geometric=geo)  # as select_terms does for the run
    delta = terms_delta(cfg, sel)
    assert delta is not None, sel.summary
    return ScaraTerms(cfg, truth, steps, geo, sel, delta, measured)
