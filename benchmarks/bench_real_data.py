"""``--model auto`` against the geometric fit on real measurements of real robots (issue 30).

    .venv/bin/python benchmarks/bench_real_data.py [--boby-klimchik DIR] [--figaroh PYTHON] [--splits 200]

Per data set: the poses, the selection's cross-validated RMS position error of the geometric model
and of the chosen model (the CV that chose it: optimistic for the chosen one), the *nested*
cross-validation (leave-one-out outside, the whole selection repeated inside every training set:
the held-out error a new pose would see) of both, the change, the terms chosen on all data and how
often each outer fold chose them, and the peer's published figure where there is one. With
``--figaroh PYTHON`` (a Python that has FIGAROH, as for ``bench_core.py``), FIGAROH's geometric
calibration (``BaseCalibration``, its default cost) of every leave-one-out training set of a pose
data set, scored on the pose left out: the peer's held-out RMS on the same split. No asserts.

Then every model on the same folds (issue 38, :mod:`benchmarks._real_splits`): leave-one-out and
``--splits`` seeded random splits (a fifth of the poses held out, 29/7 for the FANUC's 36), for
the geometric fit, auto (selected anew on every training set) and each candidate family forced:
the leave-one-out RMS with its change and p, the per-split changes' median and quartiles, the
shares of splits better and worse and p; with ``--figaroh``, FIGAROH with its non-geometric
(elasticity) option on the same folds, and the share of splits where auto is at least as good.

Data sets:

* ``ur10e-figaroh`` — a UR10e (33 kg arm, 12.5 kg payload class), 23 poses measured by a camera on a
  marker, shipped with FIGAROH's examples (Apache-2.0): ``benchmarks/data/ur10e_figaroh_calibration.csv``
  with the robot ``benchmarks/data/ur10e.dh.csv`` (UR's published DH). Position objective, σ 0.5 mm
  (the camera's scatter), marker point unknown. FIGAROH publishes no accuracy figure for this set.
* ``fanuc-r2000ic`` — a FANUC R-2000iC/165F (a 1.2 t arm, 165 kg payload class), 36 poses of a nest
  of three laser-tracker reflectors, one joint swept at a time (R. A. Boby, A. Klimchik, "Combination
  of geometric and parametric approaches for kinematic identification of an industrial robot",
  RCIM). Its repository (github.com/RABKKK/LaserTrackerPoseData4KinIdent) states no licence, so
  the data are not kept here: give a clone with ``--boby-klimchik DIR`` (the file N1N2N3Jval.csv;
  its columns 16–21 are J1 … J6 [deg], 1–9 the reflectors [mm]). Robot:
  ``benchmarks/data/fanuc_r2000ic_165f.dh.csv`` (data-sheet DH, FANUC's J2/J3 joint map). Pose
  objective (σ 15 µm, 20″), nest point unknown. No peer figure published for this set.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks import _real_splits as rs  # noqa: E402
from station.core.identification.identify import identify  # noqa: E402
from station.core.measurement.measurements import MeasurementSet  # noqa: E402
from station.core.terms.selection import nested_cv, select_model  # noqa: E402
from station.core.units import ARCSEC, UM  # noqa: E402
from station.io.datafile import read_measurement_file  # noqa: E402
from station.io.robot.formats import read_dh_file  # noqa: E402

DATA = Path(__file__).with_name("data")
NEST_HEADER = ("q1 [deg],q2 [deg],q3 [deg],q4 [deg],q5 [deg],q6 [deg],x1 [mm],y1 [mm],z1 [mm],x2 [mm],y2 [mm],"
               "z2 [mm],x3 [mm],y3 [mm],z3 [mm]")


def _load(robot: Path, data: Path, sigma_mm: float, sigma_rad: float):
    model, jmap = read_dh_file(robot)
    mf = read_measurement_file(data, model)
    q = jmap.to_model(mf.joints)
    if mf.kind == "pose":
        return model, MeasurementSet("pose", q, mf.measured, np.array([sigma_mm] * 3 + [sigma_rad] * 3))
    return model, MeasurementSet("position", q, mf.measured, np.array([sigma_mm] * 3))


def _fanuc_file(folder: Path, out: Path) -> Path:
    a = np.loadtxt(folder / "N1N2N3Jval.csv")
    np.savetxt(out, np.column_stack([a[:, 15:21], a[:, :9]]), delimiter=",", header=NEST_HEADER, comments="",
               fmt="%.10g")
    return out


def figaroh_loo_um(python: str, model, d: MeasurementSet) -> float:
    """FIGAROH's leave-one-out held-out RMS position error [µm] on pose data ``d`` (see the module)."""
    from benchmarks.bench_core import figaroh_figures

    n = d.n_items
    sets = {}
    for i in range(n):
        train = np.setdiff1d(np.arange(n), [i])
        sets[i] = (d.joints[train], d.subset(train))
    out = figaroh_figures(python, model, sets, d.joints, 1)
    e2 = [float(np.sum((np.asarray(out[i]["held_out_positions_m"][i]) * 1e3 - d.measured[i, :3, 3]) ** 2))
          for i in range(n)]
    return float(np.sqrt(np.mean(e2))) / UM


PEER = "FIGAROH elasticity"


def same_folds(model, d, geo_fit, n_splits: int, figaroh: str | None = None) -> None:
    """Every model on the same folds (see the module): leave-one-out, then ``n_splits`` random splits;
    with ``figaroh`` (pose data), FIGAROH with its elasticity option on the same folds."""
    forced = tuple((f,) for f in rs.candidates(model))
    n_test = max(1, round(d.n_items / 5))
    peer = figaroh if d.kind == "pose" else None
    t0 = time.process_time()
    folds = [np.array([i]) for i in range(d.n_items)]
    loo = rs.score_folds(model, d, folds, geo_fit, forced)
    extra = {PEER: np.concatenate(rs.figaroh_fold_e2(peer, model, d, folds))} if peer else None
    print(f"every model on the same folds: leave-one-out ({d.n_items} folds; auto chose {rs.chosen_line(loo)})")
    print("\n".join(rs.loo_table(loo, extra)))
    if n_splits:
        folds = rs.random_splits(d.n_items, n_test, n_splits)
        spl = rs.score_folds(model, d, folds, geo_fit, forced)
        extra_s = {PEER: rs.figaroh_fold_e2(peer, model, d, folds)} if peer else None
        print(f"{n_splits} seeded random {d.n_items - n_test}/{n_test} splits: held-out RMS per split against the "
              f"geometric fit's (auto chose {rs.chosen_line(spl)})")
        print("\n".join(rs.split_table(spl, extra_s, PEER if peer else None)))
    print(f"(folds scored in {time.process_time() - t0:.0f} s CPU of this process"
          + (", FIGAROH's runs beside)" if peer else ")"))


def run_set(name: str, robot: Path, data: Path, sigma_mm: float, sigma_rad: float, peer: str,
            figaroh: str | None = None, n_splits: int = 0) -> None:
    model, d = _load(robot, data, sigma_mm, sigma_rad)

    def geo_fit(dd):
        return identify(model, dd, tool_unknown=True)

    t0 = time.perf_counter()
    geo = geo_fit(d)
    sel = select_model(model, d, geometric=geo)
    t_sel = time.perf_counter() - t0
    nest = nested_cv(model, d, geometric_fit=geo_fit)
    geo_cv = sel.table[0].cv_rms_mm
    auto_cv = next((r.cv_rms_mm for r in sel.table if r.families == sel.chosen and r.kept), geo_cv)
    change = 100 * (nest.auto_rms_mm - nest.geometric_rms_mm) / nest.geometric_rms_mm
    folds = Counter(f for c in nest.chosen for f in c)
    print(f"\n== {name}: {model.name}, {d.n_items} {d.kind} measurements ({robot.name}, {data.name})")
    print(f"selection CV ({sel.cv}): geometric {geo_cv / UM:.1f} µm, auto {auto_cv / UM:.1f} µm "
          f"({100 * (auto_cv - geo_cv) / geo_cv:+.1f} %); selection and fit {t_sel * 1e3:.0f} ms")
    print(f"nested CV held-out ({nest.cv} outside, the selection repeated inside): geometric "
          f"{nest.geometric_rms_mm / UM:.1f} µm, auto {nest.auto_rms_mm / UM:.1f} µm ({change:+.1f} %)")
    print(f"terms chosen on all data: {', '.join(sel.chosen) or 'none (geometric)'}; chosen by the outer folds: "
          + (", ".join(f"{f} {n}/{len(nest.chosen)}" for f, n in folds.most_common()) or "none"))
    for t in sel.fit.terms_dict():
        print(f"  {t['name']:18s} {t['value']:+.4g} ± {t['sigma']:.2g} {t['unit']}")
    print(f"peer figure: {peer}")
    if figaroh and d.kind == "pose":
        print(f"FIGAROH run here (geometric, BaseCalibration), leave-one-out held-out: "
              f"{figaroh_loo_um(figaroh, model, d):.1f} µm (the station's geometric: {nest.geometric_rms_mm / UM:.1f} µm)")
    elif figaroh:
        print("FIGAROH run here: not on position data (its calibration here takes full poses)")
    same_folds(model, d, geo_fit, n_splits, figaroh)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--boby-klimchik", metavar="DIR",
                    help="a clone of github.com/RABKKK/LaserTrackerPoseData4KinIdent (FANUC R-2000iC/165F)")
    ap.add_argument("--figaroh", metavar="PYTHON", help="a Python that has FIGAROH: its leave-one-out figure too")
    ap.add_argument("--splits", type=int, default=200, help="seeded random splits per data set (0: leave-one-out only)")
    args = ap.parse_args(argv)
    print("real data: --model auto against the geometric fit (RMS position errors, µm)")
    run_set("ur10e-figaroh", DATA / "ur10e.dh.csv", DATA / "ur10e_figaroh_calibration.csv", 0.5, 20 * ARCSEC,
            "none published for this set", args.figaroh, args.splits)
    if args.boby_klimchik:
        with tempfile.TemporaryDirectory() as tmp:
            f = _fanuc_file(Path(args.boby_klimchik), Path(tmp) / "fanuc_nest.csv")
            run_set("fanuc-r2000ic", DATA / "fanuc_r2000ic_165f.dh.csv", f, 0.015, 20 * ARCSEC,
                    "none published for this set", args.figaroh, args.splits)
    else:
        print("\n== fanuc-r2000ic: skipped (no licence to keep its data here; give --boby-klimchik DIR, a clone of "
              "github.com/RABKKK/LaserTrackerPoseData4KinIdent)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
