"""Is the reported σ honest? (issue 38's "a reported σ matches the Monte Carlo scatter"): on the
built-in SCARA's simulated robot and on the six-axis bench arm, the predicted pose σ after a
geometric identification beside the real estimation error and the Monte Carlo scatter.

A model-level rehearsal per seed: the simulator's true robot (``simulators.cell.CellTruth.generate``,
the built-in cell's SR 800 with 5 µm repeatability per joint at 450 mm; ``six_axis_truth``, 10 µm at
each joint's lever), measured as poses at ``--poses`` poses spread over the workspace with the
cells' measurement σ (SCARA 6 µm and 6″ as the built-in cell's [identification]; six-axis 15 µm
and 15″), every visit's joints drawn through the truth's repeatability. No backlash and no joint
errors: the only noise the measurement σ leaves out is the repeatability, so the ratio says what
leaving it out costs.

* ``RP``: the "data sheet" figure, measured from the truth as ISO 9283 §7.2.2 does (30 cycles at 5
  poses, RP = l̄ + 3 S_l, the worst pose); what a robot file's ``repeatability_mm`` states.
* ``actual``: the RMS 3-D error of the identified model against the truth's at 200 held-out poses
  (in the body frame, so the set-up counts; no repeatability in it), root mean square over
  ``--draws`` noise draws on the same robot and poses.
* ``meas``: the linear σ there from the measurement σ alone (the station before the repeatability
  key); ``rp``: with the robot file's RP in the noise model; ``s0``: the a-posteriori variance
  factor of the fit without the key and ``post``: the σ it reports (scaled by s0 where the χ² test
  at 5 % says the noise is larger); ``MC``: the Monte Carlo scatter (``monte_carlo``, the joints
  drawn through the truth's repeatability), propagated to the same poses.

Prints the ratios actual/σ per seed and their median over seeds (1.0 = honest). Then the case of
issue 38's closing note, the six-axis arm with joint errors under ``--model auto``
(:func:`terms_section`).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_sigma_honesty.py [--seeds 5] [--draws 10] [--sets 300]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from simulators.cell import CellTruth  # noqa: E402
from simulators.six_axis_cell import six_axis_truth  # noqa: E402
from simulators.truth_kinematics import true_forward  # noqa: E402
from station.core.accuracy.iso9283 import iso9283_pose  # noqa: E402
from station.core.identification.identify import identify  # noqa: E402
from station.core.kinematics.forward import forward  # noqa: E402
from station.core.kinematics.poses import spread_joints  # noqa: E402
from station.core.measurement.measurements import MeasurementSet, add_noise  # noqa: E402
from station.core.measurement.repeatability import with_repeatability  # noqa: E402
from station.core.measurement.uncertainty import monte_carlo, pose_accuracy  # noqa: E402
from station.core.units import ARCSEC  # noqa: E402

ARMS = {
    # name: (truth, measurement σ [µm, ″], identification poses)
    "scara (built-in cell)": (lambda seed: CellTruth.generate(seed=seed), (6.0, 6.0), 60),
    "six-axis bench arm": (six_axis_truth, (15.0, 15.0), 200),
}


def datasheet_rp(truth, rng: np.random.Generator, poses: int = 5, cycles: int = 30) -> float:
    """ISO 9283 RP [mm] of the true robot: ``cycles`` visits of ``poses`` poses, the worst pose."""
    kinds = [t.joint for t in truth.model.transforms]
    q = spread_joints(truth.model, poses, rng)
    rps = []
    for qi in q:
        att = true_forward(kinds, truth.params, qi + rng.standard_normal((cycles, qi.size)) * truth.repeatability)
        rps.append(iso9283_pose(att[:, :3, 3].mean(axis=0), att[:, :3, 3]).RP)
    return max(rps)


def _rms_sigma(model, params, idx, cov, q) -> float:
    s = pose_accuracy(model, params, idx, cov, q, setup=True).sigma[:, :3]
    return float(np.sqrt(np.mean(np.sum(s**2, axis=1))))


def one_seed(make, sig_um, n_poses: int, seed: int, draws: int, n_sets: int) -> dict:
    truth = make(seed)
    model, p_true = truth.model, truth.params
    kinds = [t.joint for t in model.transforms]
    rng = np.random.default_rng(np.random.SeedSequence([seed, 3838]))
    rp = datasheet_rp(truth, rng)
    sig = np.array([sig_um[0] * 1e-3] * 3 + [sig_um[1] * ARCSEC] * 3)
    q = spread_joints(model, n_poses, rng)
    q_h = spread_joints(model, 200, rng)
    ref = true_forward(kinds, p_true, q_h)[:, :3, 3]
    err2, s_meas, s_rp, s_post, s0 = [], [], [], [], []
    for _ in range(draws):
        T = true_forward(kinds, p_true, q + rng.standard_normal(q.shape) * truth.repeatability)
        data = MeasurementSet("pose", q, T, sig)
        data = data.with_measured(add_noise(data, T, rng))
        plain = identify(model, data)
        keyed = identify(model, MeasurementSet("pose", q, data.measured, with_repeatability(sig, rp)))
        e = forward(model, q_h, plain.params, setup=True)[:, :3, 3] - ref
        err2.append(float(np.mean(np.sum(e**2, axis=1))))
        f = plain.variance.factor if plain.variance else 1.0
        post = _rms_sigma(model, plain.params, plain.chosen_index, plain.uncertainty.covariance, q_h)
        s_post.append(post)
        s_meas.append(post / f)
        s_rp.append(_rms_sigma(model, keyed.params, keyed.chosen_index,
                               np.asarray(keyed.uncertainty.covariance) / (keyed.variance.factor if keyed.variance
                                                                           else 1.0) ** 2, q_h))
        s0.append(plain.variance.s0 if plain.variance else float("nan"))
    exact = MeasurementSet("pose", q, true_forward(kinds, p_true, q), sig)
    mc = monte_carlo(model, exact, p_true, plain.chosen_index, n_sets, rng, sigma_joints=truth.repeatability)
    cov_mc = np.cov(mc.estimates[np.all(np.isfinite(mc.estimates), axis=1)], rowvar=False)
    actual = float(np.sqrt(np.mean(err2)))
    return {"seed": seed, "rp_um": rp * 1e3, "actual_um": actual * 1e3, "meas_um": np.mean(s_meas) * 1e3,
            "rp_sigma_um": np.mean(s_rp) * 1e3, "s0": float(np.median(s0)), "post_um": np.mean(s_post) * 1e3,
            "mc_um": _rms_sigma(model, p_true, plain.chosen_index, cov_mc, q_h) * 1e3}


def terms_section(seeds: list[int]) -> None:
    """The case of issue 38's closing note: ``bench_six_axis.py --terms``'s rehearsal (the six-axis
    arm with compliance and cyclic joint errors, the station's design of ~450 poses, ``--model auto``),
    its estimation error beside auto's linear σ as the station had it, with the a-posteriori factor,
    and with the robot file's RP in the weights."""
    from benchmarks._six_axis_terms import design_poses, rehearse

    print("six-axis arm with joint errors, --model auto on the station's design (bench_six_axis.py --terms): "
          "estimation error against the truth's own model at 200 held-out poses and auto's σ there [µm]")
    print(f"{'seed':>4} {'RP':>6} {'est':>6} {'pred':>6} {'s0':>5} {'post':>6} {'rp':>6} {'s0 rp':>5} {'post rp':>7}  "
          f"{'est/pred':>8} {'est/post':>8} {'est/rp':>6} {'est/post rp':>11}")
    rows = []
    for seed in seeds:
        design = design_poses(six_axis_truth(seed).model, np.random.default_rng(np.random.SeedSequence([seed, 3031])))
        rp = datasheet_rp(six_axis_truth(seed), np.random.default_rng(np.random.SeedSequence([seed, 3838])))
        a, b = rehearse(seed, design=design), rehearse(seed, design=design, rp_mm=rp)
        r = {"est": a["estimation_um"], "pred": a["predicted_um"], "post": a["reported_um"], "rp": b["predicted_um"],
             "post_rp": b["reported_um"], "est_rp": b["estimation_um"]}
        rows.append(r)
        print(f"{seed:>4} {rp * 1e3:6.1f} {r['est']:6.2f} {r['pred']:6.2f} {a['s0']:5.2f} {r['post']:6.2f} "
              f"{r['rp']:6.2f} {b['s0']:5.2f} {r['post_rp']:7.2f}  {r['est'] / r['pred']:8.2f} {r['est'] / r['post']:8.2f} "
              f"{r['est_rp'] / r['rp']:6.2f} {r['est_rp'] / r['post_rp']:11.2f}", flush=True)
    med = {k: statistics.median(r[e] / r[k] for r in rows)
           for k, e in (("pred", "est"), ("post", "est"), ("rp", "est_rp"), ("post_rp", "est_rp"))}
    print(f"median over {len(rows)} seeds: est/pred {med['pred']:.2f}, est/post (a-posteriori) {med['post']:.2f}, "
          f"est/rp (RP key) {med['rp']:.2f}, est/post rp (both) {med['post_rp']:.2f}\n", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="seeds 1 … N")
    ap.add_argument("--draws", type=int, default=10, help="noise draws per seed (the actual error's mean square)")
    ap.add_argument("--sets", type=int, default=300, help="Monte Carlo sets per seed")
    ap.add_argument("--no-terms", action="store_true", help="leave out the six-axis --model auto section (~40 s a seed)")
    args = ap.parse_args(argv)
    for arm, (make, sig_um, n_poses) in ARMS.items():
        print(f"{arm}: {n_poses} pose measurements (σ {sig_um[0]:g} µm, {sig_um[1]:g}″), the joints through the "
              f"truth's repeatability; {args.draws} draws per seed; pose σ RMS at 200 held-out poses [µm]")
        print(f"{'seed':>4} {'RP':>6} {'actual':>7} {'meas':>6} {'rp':>6} {'s0':>5} {'post':>6} {'MC':>6}  "
              f"{'act/meas':>8} {'act/rp':>6} {'act/post':>8} {'MC/rp':>6}")
        rows = []
        for seed in range(1, args.seeds + 1):
            r = one_seed(make, sig_um, n_poses, seed, args.draws, args.sets)
            rows.append(r)
            print(f"{seed:>4} {r['rp_um']:6.1f} {r['actual_um']:7.2f} {r['meas_um']:6.2f} {r['rp_sigma_um']:6.2f} "
                  f"{r['s0']:5.2f} {r['post_um']:6.2f} {r['mc_um']:6.2f}  {r['actual_um'] / r['meas_um']:8.2f} "
                  f"{r['actual_um'] / r['rp_sigma_um']:6.2f} {r['actual_um'] / r['post_um']:8.2f} "
                  f"{r['mc_um'] / r['rp_sigma_um']:6.2f}", flush=True)

        def med(key_a: str, key_b: str) -> float:
            return statistics.median(r[key_a] / r[key_b] for r in rows)  # noqa: B023

        print(f"median over {len(rows)} seeds: actual/meas {med('actual_um', 'meas_um'):.2f}, actual/rp "
              f"{med('actual_um', 'rp_sigma_um'):.2f}, actual/post (no key, a-posteriori) {med('actual_um', 'post_um'):.2f}, "
              f"MC/meas {med('mc_um', 'meas_um'):.2f}, MC/rp {med('mc_um', 'rp_sigma_um'):.2f}\n", flush=True)
    if not args.no_terms:
        terms_section(list(range(1, args.seeds + 1)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
