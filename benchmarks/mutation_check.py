"""Mutation check: a wrong forward kinematics in ``station.core`` must make the end-to-end tests
fail (issue 33, part 7: "tests that cannot agree with themselves").

The simulated truth has its own kinematics (simulators/truth_kinematics.py), so a fault in the
station's kinematics is a robot the station models wrongly: identification, correction and
verification must show it. This script copies the work tree, plants one fault at a time in the
copy's ``station/core/kinematics/forward.py`` (and, for the symmetric slips a shared simulator would have
cancelled, in the probe head's face normals and the driver's word order), runs the end-to-end
tests there, and prints whether each mutant was killed (the tests failed) or survived. The
unmutated copy runs first and must pass.

    .venv/bin/python benchmarks/mutation_check.py            # the default end-to-end tests
    .venv/bin/python benchmarks/mutation_check.py TEST ...   # pytest node ids of your choice

Exit 0 when the baseline passes and every mutant is killed, 1 otherwise.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
KINEMATICS = "station/core/kinematics/forward.py"
GRID = "station/core/table/values.py"  # the interpolation rule, its one implementation

#: a SCARA and a six-axis calibration, end to end against the simulated cells
DEFAULT_TESTS = (
    "tests/cell/test_pipeline.py::test_simulated_calibration_meets_the_targets",
    "tests/cell/test_six_axis_e2e.py",
)
#: the table's edges through both interpolations and the motion guard
TABLE_EDGES = ("tests/core/test_table_edges.py",)
#: the controller's IK held to the station's, and the SCARA end to end
CONTROLLER_IK = ("tests/simulators/test_arm_kinematics.py",
                 "tests/cell/test_pipeline.py::test_simulated_calibration_meets_the_targets")
#: the built-in robots' plausibility and a SCARA's soft limits to the degree
DEGREES = ("tests/io/test_builtin_robots.py",
           "tests/drivers/test_controller_sim.py::test_soft_limit_and_unreachable_rejected")

#: (what the fault is, the file, ((the line as it is, the line with the fault), ...), the tests
#: that must kill it)
MUTANTS = (
    # subtle: the fit absorbs it into the joint offsets, so only a truth that does not share the
    # station's kinematics (the oracle, the after/oracle lower bound) can show it
    ("every revolute joint 1 mrad off (a fit absorbs it)", KINEMATICS,
     (("        c, s = np.cos(q)[..., None], np.sin(q)[..., None]",
       "        c, s = np.cos(q + 1e-3)[..., None], np.sin(q + 1e-3)[..., None]"),), DEFAULT_TESTS),
    # gross: the plan's reachability checks already refuse the cell before any motion
    ("joint 2 turns the other way", KINEMATICS,
     (("            _turn(T, spec.joint, q[..., j])",
       "            _turn(T, spec.joint, -q[..., j] if j == 1 else q[..., j])"),), DEFAULT_TESTS),
    ("a prismatic joint moves along -z", KINEMATICS,
     (("        T[..., :3, 3] += T[..., :3, 2] * q[..., None]", "        T[..., :3, 3] -= T[..., :3, 2] * q[..., None]"),),
     DEFAULT_TESTS),
    ("a revolute joint's sine flipped (a mirrored rotation)", KINEMATICS,
     (("        np.multiply(y, s, out=col0)", "        np.multiply(y, -s, out=col0)"),
      ("        x *= s\n", "        x *= -s\n")), DEFAULT_TESTS),
    # symmetric slips that a simulator sharing the station's or the driver's code would have made
    # too, so that they cancelled: the simulated head now touches the cube with its own physics
    # (simulators/probe_contact.py), the simulated program reads words with its own code
    # (simulators/program_words.py)
    ("the tip sphere inside its face (readings and solver)", "station/core/probe/geometry.py",
     (("        s = (rho + hM - nb) / incidence", "        s = (-rho + hM - nb) / incidence"),
      ('    f = np.einsum("ni,ni->n", n_f, q) - geom.tip_radii', '    f = np.einsum("ni,ni->n", n_f, q) + geom.tip_radii')),
     DEFAULT_TESTS),
    ("the driver's BIG word order is low word first (both ways)", "drivers/controller_map.py",
     (("    return [hi, lo] if order is WordOrder.BIG else [lo, hi]",
       "    return [lo, hi] if order is WordOrder.BIG else [hi, lo]"),
      ("    hi, lo = (regs[0], regs[1]) if order is WordOrder.BIG else (regs[1], regs[0])",
       "    hi, lo = (regs[1], regs[0]) if order is WordOrder.BIG else (regs[0], regs[1])")), DEFAULT_TESTS),
    # issue 42, the slips that survived. An off-by-one in the table's cell index (the motion
    # guard's out-of-table refusal was never tested) ...
    ("the table lets a point one node step beyond its last through", GRID,
     (("            bad = (u < -1e-6) | (u > a.count - 1 + 1e-6)",
       "            bad = (u < -1e-6) | (u > a.count + 1e-6)"),), TABLE_EDGES),
    ("the table lets a point one node step before its first through", GRID,
     (("            bad = (u < -1e-6) | (u > a.count - 1 + 1e-6)",
       "            bad = (u < -1 - 1e-6) | (u > a.count - 1 + 1e-6)"),), TABLE_EDGES),
    ("the table's last cell starts at its last node (one off)", GRID,
     (("            i0 = np.minimum(np.floor(u).astype(np.int64), a.count - 2)",
       "            i0 = np.minimum(np.floor(u).astype(np.int64), a.count - 1)"),), TABLE_EDGES),
    ("the periodic yaw's last cell does not wrap to node 0", GRID,
     (("            i1 = (i0 + 1) % a.count", "            i1 = np.minimum(i0 + 1, a.count - 1)"),), TABLE_EDGES),
    # ... revolute limits left unconverted from degrees (57× too wide) ...
    ("revolute limits left in degrees (57× too wide)", "station/core/kinematics/model.py",
     (('            scale = a_scale if joint == "revolute" else l_scale',
       '            scale = 1.0 if joint == "revolute" else l_scale'),), DEGREES),
    # ... and a slip in the station's IK that the simulated controller, calling it, made too
    ("the SCARA's elbow sign flipped in the station's IK", KINEMATICS,
     (("    beta = elbow * np.arccos(np.clip(c_beta, -1.0, 1.0))",
       "    beta = -elbow * np.arccos(np.clip(c_beta, -1.0, 1.0))"),), CONTROLLER_IK),
)


def _copy_tree(dest: Path) -> None:
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           check=True, capture_output=True).stdout.decode().split("\0")
    for name in filter(None, files):
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)


def _run(copy: Path, tests: list[str]) -> tuple[bool, float, str]:
    # the copy's packages first: the project's editable install would otherwise import the original
    env = dict(os.environ, PYTHONPATH=str(copy))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "-p", "no:xdist",
                           *tests], cwd=copy, env=env, capture_output=True, text=True)
    lines = proc.stdout.strip().splitlines() or [""]
    why = next((ln[1:].strip() for ln in lines if ln.startswith("E ")), "")  # the first failed assertion
    return proc.returncode == 0, time.perf_counter() - t0, f"{lines[-1]}  {why[:110]}".rstrip()


def main(argv: list[str]) -> int:
    tests = argv  # empty: each mutant against its own targets
    with tempfile.TemporaryDirectory(prefix="mutation-") as tmp:
        copy = Path(tmp)
        _copy_tree(copy)
        where = subprocess.run([sys.executable, "-c", "import station.core.kinematics.forward as k; print(k.__file__)"],
                               cwd=copy, env=dict(os.environ, PYTHONPATH=str(copy)), capture_output=True,
                               text=True).stdout.strip()
        if not where.startswith(str(copy)):
            print(f"the copy imports the station from {where}, not from the copy", file=sys.stderr)
            return 1
        # every target once, unmutated: a mutant's failure must be the fault's, not the tree's
        every = list(tests) or list(dict.fromkeys(t for *_, targets in MUTANTS for t in targets))
        ok, seconds, tail = _run(copy, every)
        print(f"{'baseline (no fault)':<62} {'passes' if ok else 'FAILS':<9} {seconds:6.0f} s  {tail}")
        survived = 0
        for name, path, edits, targets in MUTANTS:
            source = (copy / path).read_text(encoding="utf-8")
            faulty = source
            for line, fault in edits:
                if source.count(line) != 1:
                    print(f"{name:<62} the line to mutate is not found once in {path}", file=sys.stderr)
                    return 1
                faulty = faulty.replace(line, fault)
            (copy / path).write_text(faulty, encoding="utf-8")
            passed, seconds, tail = _run(copy, list(tests) or list(targets))
            survived += passed
            print(f"{name:<62} {'SURVIVED' if passed else 'killed':<9} {seconds:6.0f} s  {tail}")
            (copy / path).write_text(source, encoding="utf-8")
    print(f"killed / planted: {len(MUTANTS) - survived} / {len(MUTANTS)} "
          f"({'the given' if tests else 'each slip against its own'} test targets)")
    return 0 if ok and not survived else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
