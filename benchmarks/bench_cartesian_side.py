"""From which side a SCARA's Cartesian touches arrive (issue 40), per seed of a simulated cell.

Verification with the table active ends in a Cartesian move, to which the controller adds the
table's joint correction Δq. The simulated arm (simulators/cell.py) lags each joint by half its
backlash against the direction of its last move: a joint that arrives from the other side than at
identification lands on the other flank. This runs ``station calibrate --simulated [CONFIG] --seed N``
in-process and prints per seed the outcome, before / after / oracle RMS, ×gain and after/oracle,
and per verification phase (before, after, oracle) how many Cartesian touches had a revolute joint
arrive against its approach side, read from the simulator's own direction state at each probe
reading; with the largest |Δq| of a revolute joint and the smallest last step of one.

    .venv/bin/python benchmarks/bench_cartesian_side.py 0 1 2 3 4 5              # the built-in cell
    .venv/bin/python benchmarks/bench_cartesian_side.py --config examples/scara_arc/cell.toml 1 2 3
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

import simulators.cell as sim_cell
import simulators.controller_server as sim_ctl
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.ui.simulated_cell import load_cell

_seen: dict[str, Any] = {"target": None, "phase": "?", "reads": [], "revolute": None}


def _watch() -> None:
    """Observe the simulator (never change it): the joints of each Cartesian target and its Δq,
    and at each probe reading after one, the joints' directions of arrival and last step."""
    target = sim_ctl.SimulatedController.cartesian_target
    values = sim_cell.SimulatedCell.probe_values

    def cartesian_target(self, pose, elbow):
        q = target(self, pose, elbow)
        nominal = self.kinematics.scara_inverse(sim_ctl.pose_matrix(np.asarray(pose, float)), elbow)
        _seen["target"] = (q.copy(), q - nominal)
        return q

    def probe_values(self):
        t = _seen["target"]
        if t is not None and np.allclose(self._cmd, t[0]):
            _seen["revolute"] = np.array([k == "revolute" for k in self.truth.model.joint_types])
            _seen["reads"].append((_seen["phase"], self._direction.copy(), t[1], self._cmd - self._prev_cmd))
        return values(self)

    sim_ctl.SimulatedController.cartesian_target = cartesian_target  # type: ignore[method-assign]
    sim_cell.SimulatedCell.probe_values = probe_values  # type: ignore[method-assign]


def _emit(e: Any) -> None:
    if type(e).__name__ == "PhaseChanged":
        d = str(getattr(e, "detail", ""))
        _seen["phase"] = next((p for p in ("before", "after", "oracle") if d.startswith(p)), _seen["phase"])


def one(config: str | None, seed: int) -> str:
    _seen.update(target=None, phase="?", reads=[])
    with tempfile.TemporaryDirectory() as tmp:
        s = run_calibration_session(CellRequest(config=config, simulated=True, seed=seed,
                                                db=str(Path(tmp) / "runs.sqlite")), _emit, load=load_cell)
    rms = [f"{x.rms_um:6.2f}" if x is not None else "     –" for x in (s.before, s.after, s.oracle)]
    line = (f"{seed:>4}  {s.outcome.name:8}  {'  '.join(rms)}  {s.gain or 0:6.1f}  "
            f"{s.after_vs_oracle or 0:5.3f}")
    if _seen["reads"]:
        rev = _seen["revolute"]
        phase = np.array([r[0] for r in _seen["reads"]])
        d, dq, step = (np.array([r[i] for r in _seen["reads"]]) for i in (1, 2, 3))
        against = {p: int(np.any(d[phase == p][:, rev] < 0, axis=1).sum()) for p in ("before", "after", "oracle")}
        line += (f"  {against['before']:>4} {against['after']:>4} {against['oracle']:>4}  "
                 f"{np.rad2deg(np.abs(dq[:, rev]).max()):6.3f}  {np.rad2deg(step[:, rev].min()):7.3f}")
    return line


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seeds", type=int, nargs="*", default=list(range(6)))
    ap.add_argument("--config", default=None, help="a cell.toml (default: the built-in cell)")
    args = ap.parse_args()
    _watch()
    print(f"cell: {args.config or 'built-in'}")
    print(f"{'seed':>4}  {'outcome':8}  {'before':>6}  {'after':>6}  {'oracle':>6}  {'gain':>6}  {'a/o':>5}  "
          f"against the approach side: {'bef':>4} {'aft':>4} {'orc':>4}  max|Δq|°  min step°")
    for seed in args.seeds:
        print(one(args.config, seed), flush=True)


if __name__ == "__main__":
    main()
