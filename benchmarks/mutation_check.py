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

#: (what the fault is, the file, ((the line as it is, the line with the fault), ...))
MUTANTS = (
    # subtle: the fit absorbs it into the joint offsets, so only a truth that does not share the
    # station's kinematics (the oracle, the after/oracle lower bound) can show it
    ("every revolute joint 1 mrad off (a fit absorbs it)", KINEMATICS,
     (("        c, s = np.cos(q), np.sin(q)", "        c, s = np.cos(q + 1e-3), np.sin(q + 1e-3)"),)),
    # gross: the plan's reachability checks already refuse the cell before any motion
    ("joint 2 turns the other way", KINEMATICS,
     (("            T = T @ _joint_matrix(spec.joint, q[..., j])",
       "            T = T @ _joint_matrix(spec.joint, -q[..., j] if j == 1 else q[..., j])"),)),
    ("a prismatic joint moves along -z", KINEMATICS,
     (("        T[..., 2, 3] = q", "        T[..., 2, 3] = -q"),)),
    ("a revolute joint's sine flipped (a mirrored rotation)", KINEMATICS,
     (("        T[..., 0, 0], T[..., 0, 1], T[..., 1, 0], T[..., 1, 1] = c, -s, s, c",
       "        T[..., 0, 0], T[..., 0, 1], T[..., 1, 0], T[..., 1, 1] = c, s, -s, c"),)),
    # symmetric slips that a simulator sharing the station's or the driver's code would have made
    # too, so that they cancelled: the simulated head now touches the cube with its own physics
    # (simulators/probe_contact.py), the simulated program reads words with its own code
    # (simulators/program_words.py)
    ("the tip sphere inside its face (readings and solver)", "station/core/probe/geometry.py",
     (("        s = (rho + hM - nb) / incidence", "        s = (-rho + hM - nb) / incidence"),
      ('    f = np.einsum("ni,ni->n", n_f, q) - geom.tip_radii', '    f = np.einsum("ni,ni->n", n_f, q) + geom.tip_radii'))),
    ("the driver's BIG word order is low word first (both ways)", "drivers/controller_map.py",
     (("    return [hi, lo] if order is WordOrder.BIG else [lo, hi]",
       "    return [lo, hi] if order is WordOrder.BIG else [hi, lo]"),
      ("    hi, lo = (regs[0], regs[1]) if order is WordOrder.BIG else (regs[1], regs[0])",
       "    hi, lo = (regs[1], regs[0]) if order is WordOrder.BIG else (regs[0], regs[1])"))),
)

#: a SCARA and a six-axis calibration, end to end against the simulated cells
DEFAULT_TESTS = (
    "tests/cell/test_pipeline.py::test_simulated_calibration_meets_the_targets",
    "tests/cell/test_six_axis_e2e.py",
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
    tests = argv or list(DEFAULT_TESTS)
    with tempfile.TemporaryDirectory(prefix="mutation-") as tmp:
        copy = Path(tmp)
        _copy_tree(copy)
        where = subprocess.run([sys.executable, "-c", "import station.core.kinematics.forward as k; print(k.__file__)"],
                               cwd=copy, env=dict(os.environ, PYTHONPATH=str(copy)), capture_output=True,
                               text=True).stdout.strip()
        if not where.startswith(str(copy)):
            print(f"the copy imports the station from {where}, not from the copy", file=sys.stderr)
            return 1
        ok, seconds, tail = _run(copy, tests)
        print(f"{'baseline (no fault)':<58} {'passes' if ok else 'FAILS':<9} {seconds:6.0f} s  {tail}")
        survived = 0
        for name, path, edits in MUTANTS:
            source = (copy / path).read_text(encoding="utf-8")
            faulty = source
            for line, fault in edits:
                if source.count(line) != 1:
                    print(f"{name:<58} the line to mutate is not found once in {path}", file=sys.stderr)
                    return 1
                faulty = faulty.replace(line, fault)
            (copy / path).write_text(faulty, encoding="utf-8")
            passed, seconds, tail = _run(copy, tests)
            survived += passed
            print(f"{name:<58} {'SURVIVED' if passed else 'killed':<9} {seconds:6.0f} s  {tail}")
            (copy / path).write_text(source, encoding="utf-8")
    print(f"{len(MUTANTS) - survived} of {len(MUTANTS)} mutants killed by {len(tests)} end-to-end test target(s)")
    return 0 if ok and not survived else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
