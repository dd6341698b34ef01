"""Timing of the numerical core on this machine: medians of repeated runs after a warm-up.

    .venv/bin/python benchmarks/bench_core.py [--repeat 15] [--figaroh /tmp/figaroh-venv/bin/python]

The identification fit (``identify``: data checks, registration, identifiability, the fit and its
uncertainty) of 25, 100 and 1000 full poses of the SR 800 with 20 parameters, and its held-out
error: the RMS position error [µm] of the identified model against the true robot at 200 poses
not used in the fit. Then the Monte Carlo study (10 000 sets at 25 poses: time, CPU time and
peak memory) and the batched Jacobian. Each figure is printed
with its target and target/figure (> 1: faster than the target); the fits also with their best
run (on a shared machine the median carries the other load, the best run the arithmetic). No
asserts.

``--figaroh PYTHON``: the same data sets fitted by FIGAROH (PyPI ``figaroh``: ``BaseCalibration``,
``initialize()`` + ``solve()``, metres) in a benchmark-only environment that has it, never the
project's (e.g. ``python -m venv /tmp/figaroh-venv && /tmp/figaroh-venv/bin/pip install figaroh``);
its fit times, their ratio to the station's, and its held-out error on the same poses.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks._timing import median_time  # noqa: E402
from station.core.accuracy.studies import StudyInputs, perturbed  # noqa: E402
from station.core.identification.identify import identify  # noqa: E402
from station.core.kinematics.forward import forward, forward_with_jacobian  # noqa: E402
from station.core.kinematics.poses import spread_joints  # noqa: E402
from station.core.kinematics.transforms import matrix_to_pose  # noqa: E402
from station.core.measurement.measurements import synthetic_set  # noqa: E402
from station.core.measurement.uncertainty import monte_carlo  # noqa: E402
from station.io.export.model_files import export_model  # noqa: E402
from station.io.robot.files import load_robot  # noqa: E402

#: fit sizes [poses] and their targets [s]: ≥ 50× FIGAROH's at 25 and 100 poses, ≤ 50 ms at 1000
FIT_TARGETS = {25: 0.0014, 100: 0.005, 1000: 0.050}
HELD_OUT = 200
PEER = Path(__file__).with_name("_figaroh_peer.py")


def fit_times(fn, repeat: int) -> tuple[float, float]:
    """Median and best wall time [s] of ``repeat`` calls of ``fn`` after one untimed warm-up (the
    best: the arithmetic's own speed on a machine whose other load comes and goes)."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), min(times)


def held_out_um(model, params, q, true) -> float:
    """RMS position error [µm] of the model ``params`` against the true robot at joints ``q``."""
    d = forward(model, q, params)[:, :3, 3] - forward(model, q, true)[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1)))) * 1e3


def _figaroh_config(name: str, model, data_file: str, n: int, non_geometric: bool = False) -> str:
    joints = ", ".join(f'"joint_{t.name}"' for t in model.transforms if t.joint is not None)
    return f"""robot:
  name: "{model.name}"
  properties:
    joints:
      active_joints: [{joints}]
tasks:
  calibration:
    enabled: true
    type: kinematic_calibration
    parameters:
      calibration_level: "full_params"
      include_non_geometric: {"true" if non_geometric else "false"}
      outlier_threshold: 1.0
    kinematics:
      base_frame: "universe"
      tool_frame: "tool0"
    measurements:
      markers:
        - name: "{name}"
          reference_joint: "joint_{[t.name for t in model.transforms if t.joint is not None][-1]}"
          measurable_dof: [true, true, true, true, true, true]
      poses:
        base_pose: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        tool_pose: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    data:
      source_file: "{data_file}"
      number_of_samples: {n}
"""


def lumped_masses_urdf(text: str) -> str:
    """The exported URDF with the station's lumped gravity shape as inertials (issue 38), for
    FIGAROH's elasticity option, whose torques come from the URDF's masses: 1 kg at the origin of
    every joint after the first and at the tool point (:func:`station.core.terms.error_model.gravity_torques`,
    lumped). The station's URDF has no masses (kinematics only)."""
    inertial = ('<inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="1.0"/>'
                '<inertia ixx="1e-9" ixy="0" ixz="0" iyy="1e-9" iyz="0" izz="1e-9"/></inertial>')
    links = re.findall(r'<child link="(link_[^"]+|tool0)"/>', text)
    for name in links[1:]:  # not the first joint's link: its origin loads no joint the gravity turns
        text = text.replace(f'<link name="{name}"/>', f'<link name="{name}">{inertial}</link>')
    return text


def figaroh_figures(python: str, model, sets: dict, q_held, repeat: int, non_geometric: bool = False) -> dict:
    """FIGAROH's median fit time [s] and held-out positions [mm] per set, from its own venv;
    ``non_geometric``: with its elasticity option, the gravity shape the station's lumped one."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        urdf = export_model(model, "urdf", setup=True).text
        (folder / "robot.urdf").write_text(lumped_masses_urdf(urdf) if non_geometric else urdf)
        # the station's world frame is FIGAROH's universe; the set-up R is a fixed joint there
        names = [f"joint_{t.name}" for t in model.transforms if t.joint is not None]
        scale = np.array([1e-3 if t == "prismatic" else 1.0 for t in model.joint_types])
        cases = []
        for n, (q, data) in sets.items():
            pose = matrix_to_pose(data.measured)
            pose[:, :3] *= 1e-3
            head = "x1,y1,z1,phix1,phiy1,phiz1," + ",".join(names)
            rows = np.concatenate([pose, q * scale], axis=1)
            np.savetxt(folder / f"train{n}.csv", rows, delimiter=",", header=head, comments="", fmt="%.17g")
            (folder / f"config{n}.yaml").write_text(_figaroh_config("tool", model, str(folder / f"train{n}.csv"),
                                                                    len(q), non_geometric))
            cases.append({"name": str(n), "config": f"config{n}.yaml", "held_out": "held.csv"})
        np.savetxt(folder / "held.csv", q_held * scale, delimiter=",", fmt="%.17g")
        (folder / "cases.json").write_text(json.dumps(cases))
        done = subprocess.run([python, str(PEER), str(folder), str(repeat)], capture_output=True, text=True,
                              check=False)
        if done.returncode != 0:
            raise RuntimeError(f"FIGAROH run failed:\n{done.stderr[-3000:]}")
        out = json.loads(done.stdout.strip().splitlines()[-1])
    return {int(k): v for k, v in out.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15, help="timed runs per figure (>= 5)")
    ap.add_argument("--figaroh", metavar="PYTHON", help="a Python that has FIGAROH: fit the same data with it")
    ap.add_argument("--figaroh-repeat", type=int, default=3, help="timed FIGAROH runs per size")
    args = ap.parse_args(argv)
    repeat = max(5, args.repeat)

    model = load_robot("sr800")
    rng = np.random.default_rng(0)
    inputs = StudyInputs()
    true = perturbed(model, rng, inputs)
    sig = np.array([inputs.sigma_position_mm] * 3 + [inputs.sigma_angle_rad] * 3)
    sets = {}
    for n in FIT_TARGETS:
        q = spread_joints(model, n, rng)
        sets[n] = (q, synthetic_set(model, "pose", q, true, sigma=sig, rng=rng))
    q_held = spread_joints(model, HELD_OUT, rng)
    q10k = spread_joints(model, 10_000, rng)
    q25, d25 = sets[25]
    res25 = identify(model, d25)
    exact25 = synthetic_set(model, "pose", q25, true, sigma=sig)

    print(f"station core benchmark: median of {repeat} runs after a warm-up; "
          f"python {sys.version.split()[0]}, numpy {np.__version__}, {os.cpu_count()} CPUs")
    print(f"{'case':40s} {'median':>10s} {'target':>10s} {'target/median':>14s} {'held-out':>10s} {'best':>9s}")
    station = {}
    for n, target in FIT_TARGETS.items():
        data = sets[n][1]
        t, best = fit_times(functools.partial(identify, model, data), repeat)
        err = held_out_um(model, identify(model, data).params, q_held, true)
        station[n] = (t, best, err)
        print(f"{f'identify 20 params, {n} full poses':40s} {t * 1e3:8.2f}ms {target * 1e3:8.1f}ms "
              f"{target / t:14.2f} {err:8.2f}µm {best * 1e3:7.2f}ms")
    def mc10k():
        return monte_carlo(model, exact25, true, res25.chosen_index, 10_000, np.random.default_rng(1))

    cases: list[tuple[str, Callable[[], object], float, int]] = [
        ("Monte Carlo 10 000 sets x 25 poses", mc10k, 2.0, min(repeat, 5)),
        ("forward_with_jacobian, 10 000 poses", lambda: forward_with_jacobian(model, q10k, true), 0.050, repeat),
    ]
    for name, fn, target, n_runs in cases:
        t = median_time(fn, n_runs)
        print(f"{name:40s} {t * 1e3:8.2f}ms {target * 1e3:8.0f}ms {target / t:14.2f}")
    t_cpu = time.process_time()
    mc10k()
    t_cpu = time.process_time() - t_cpu
    tracemalloc.start()
    mc10k()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    # CPU time beside the wall time: on a shared machine the wall time carries the other load
    print(f"Monte Carlo 10 000 sets: CPU time {t_cpu:.2f} s (one run), peak memory {peak / 1e6:.0f} MB "
          f"(numpy's allocations, tracemalloc; target 300 MB)")
    print(f"held-out: RMS position error at {HELD_OUT} poses not fitted, identified model against the true robot")
    if args.figaroh:
        peer = figaroh_figures(args.figaroh, model, sets, q_held, max(1, args.figaroh_repeat))
        truth = forward(model, q_held, true)[:, :3, 3]
        print(f"FIGAROH (initialize + solve, median of {max(1, args.figaroh_repeat)} runs after one untimed) "
              f"on the same data:")
        print(f"{'poses':>6s} {'FIGAROH':>10s} {'station':>10s} {'FIGAROH/station':>16s} "
              f"{'held-out FIGAROH':>17s} {'held-out station':>17s}   best: FIGAROH, station, ratio")
        for n, (t, best, err) in station.items():
            f = peer[n]
            pos = np.asarray(f["held_out_positions_m"]) * 1e3
            f_err = float(np.sqrt(np.mean(np.sum((pos - truth) ** 2, axis=1)))) * 1e3
            print(f"{n:6d} {f['median_s'] * 1e3:8.1f}ms {t * 1e3:8.2f}ms {f['median_s'] / t:15.1f}× "
                  f"{f_err:15.2f}µm {err:15.2f}µm   {f['best_s'] * 1e3:.1f}ms, {best * 1e3:.2f}ms, "
                  f"{f['best_s'] / best:.1f}×")
    return 0


if __name__ == "__main__":
    sys.exit(main())
