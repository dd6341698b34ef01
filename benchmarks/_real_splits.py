"""Every model on the same folds of a real data set (issue 38): leave-one-out and seeded random
train/test splits, for the geometric fit, ``--model auto`` (the whole selection repeated on every
training set) and each candidate family forced, optionally FIGAROH on the same folds. Used by
``bench_real_data.py``; not part of the station.

Per fold every model is fitted on the training poses alone (the geometric fit with
``tool_unknown=True``, the terms' gravity torques at that fit's geometry) and scored on the held-out
poses by the nonlinear model: the squared position error [mm²] of each held-out pose.

Figures per model against the geometric fit on the same folds:

* leave-one-out: the RMS over all poses, its change, and a two-sided Wilcoxon signed-rank p on
  the per-pose held-out squared errors (paired pose by pose);
* random splits: the per-split change of the held-out RMS [%] (median and quartiles), the share of
  splits where the model is better (strictly lower RMS) and where it is worse, and a two-sided
  Wilcoxon signed-rank p on the per-split RMS differences. The splits share poses, so that p is a
  description of the spread, not an independent-sample test.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.stats import wilcoxon

from station.core.identification.identify import IdentificationResult
from station.core.kinematics.model import RobotModel
from station.core.measurement.measurements import MeasurementSet
from station.core.terms.error_model import TermSpec, available_families
from station.core.terms.selection import all_terms_basis, fit_model, held_out_e2, select_model
from station.core.units import UM
from station.errors import IdentificationError


@dataclass(frozen=True)
class FoldScores:
    """Per model (``names``) the held-out squared errors [mm²] of every fold (``e2[model][fold]``),
    and what auto chose in each fold."""

    names: tuple[str, ...]
    e2: dict[str, list[np.ndarray]]
    chosen: list[tuple[str, ...]]


def random_splits(n: int, n_test: int, count: int, seed: int = 38) -> list[np.ndarray]:
    """``count`` seeded random test sets of ``n_test`` of the ``n`` poses (sorted indices)."""
    rng = np.random.default_rng(seed)
    return [np.sort(rng.choice(n, n_test, replace=False)) for _ in range(count)]


def candidates(model: RobotModel) -> tuple[str, ...]:
    """The families forced one at a time: every family ``--model auto`` can choose from (no
    approach signs in these files: no backlash)."""
    return available_families(model, None)


def score_folds(model: RobotModel, data: MeasurementSet, folds: list[np.ndarray],
                geo_fit: Callable[[MeasurementSet], IdentificationResult], forced: tuple[tuple[str, ...], ...],
                spec: TermSpec | None = None) -> FoldScores:
    """Held-out squared errors of the geometric fit, auto and each ``forced`` model on ``folds``."""
    spec = TermSpec() if spec is None else spec
    names = ("geometric", "auto") + tuple(" + ".join(f) + " forced" for f in forced)
    e2: dict[str, list[np.ndarray]] = {k: [] for k in names}
    chosen = []
    n = data.n_items
    for test in folds:
        train = np.setdiff1d(np.arange(n), test)
        d_train, d_test = data.subset(train), data.subset(test)
        geo = geo_fit(d_train)
        basis = all_terms_basis(model, data, None, spec, geo.params)
        b_train, b_test = basis.subset(train), basis.subset(test)
        base = fit_model(model, d_train, geo, b_train, ())
        e2["geometric"].append(held_out_e2(model, d_test, base, b_test))
        sel = select_model(model, d_train, None, spec, geometric=geo, basis_all=b_train)
        e2["auto"].append(held_out_e2(model, d_test, sel.fit, b_test))
        chosen.append(sel.chosen)
        for fams, name in zip(forced, names[2:]):
            try:
                fit = fit_model(model, d_train, geo, b_train, fams, start=base)
            except IdentificationError:
                fit = base  # nothing of the family the training data can tell from the geometry
            e2[name].append(held_out_e2(model, d_test, fit, b_test))
    return FoldScores(names, e2, chosen)


def _p(diff: np.ndarray) -> float:
    diff = np.asarray(diff, dtype=float)
    return float(wilcoxon(diff).pvalue) if np.any(diff != 0) else 1.0


def loo_table(scores: FoldScores, extra: dict[str, np.ndarray] | None = None) -> list[str]:
    """Lines: leave-one-out RMS per model [µm], change against geometric, Wilcoxon p per pose."""
    per = {k: np.concatenate(v) for k, v in scores.e2.items()} | (extra or {})
    geo = per["geometric"]
    g = float(np.sqrt(np.mean(geo)))
    out = [f"  {'model':34s} {'LOO RMS':>9s} {'change':>8s} {'p':>8s}"]
    for k, e in per.items():
        r = float(np.sqrt(np.mean(e)))
        p = "" if k == "geometric" else f"{_p(e - geo):8.2g}"
        out.append(f"  {k:34s} {r / UM:7.1f}µm {100 * (r - g) / g:+7.1f}% {p:>8s}")
    return out


def split_table(scores: FoldScores, extra: dict[str, list[np.ndarray]] | None = None,
                against: str | None = None) -> list[str]:
    """Lines: per model the median [quartiles] per-split change of the held-out RMS against the
    geometric fit, shares better / worse, the Wilcoxon p; ``against``: also the share of splits
    where each model is at least as good as that one."""
    per = {k: np.array([np.sqrt(np.mean(x)) for x in v]) for k, v in (scores.e2 | (extra or {})).items()}
    geo = per["geometric"]
    out = [f"  {'model':34s} {'median change [q1, q3]':>26s} {'better':>7s} {'worse':>6s} {'p':>8s}"
           + (f"  ≥ {against}" if against else "")]
    for k, r in per.items():
        ch = 100 * (r - geo) / geo
        q1, med, q3 = np.percentile(ch, [25, 50, 75])
        line = (f"  {k:34s} {med:+8.1f}% [{q1:+6.1f}, {q3:+6.1f}] {100 * np.mean(ch < 0):6.0f}% "
                f"{100 * np.mean(ch > 0):5.0f}% " + ("" if k == "geometric" else f"{_p(r - geo):8.2g}"))
        if against and k != against:
            line += f"  {100 * np.mean(r <= per[against]):4.0f}%"
        out.append(line)
    return out


def chosen_line(scores: FoldScores) -> str:
    c = Counter(" + ".join(f) or "nothing" for f in scores.chosen)
    return ", ".join(f"{k} {v}/{len(scores.chosen)}" for k, v in c.most_common())


def figaroh_fold_e2(python: str, model: RobotModel, data: MeasurementSet, folds: list[np.ndarray],
                    non_geometric: bool = True) -> list[np.ndarray]:
    """FIGAROH's held-out squared position errors [mm²] on ``folds`` (pose data): its calibration of
    every training set (``non_geometric``: its elasticity option on, the lumped gravity shape),
    scored at the held-out poses, all in one run of its own Python."""
    from benchmarks.bench_core import figaroh_figures

    n = data.n_items
    sets = {}
    for k, test in enumerate(folds):
        train = np.setdiff1d(np.arange(n), test)
        sets[k] = (data.joints[train], data.subset(train))
    out = figaroh_figures(python, model, sets, data.joints, 0, non_geometric=non_geometric)
    meas = data.measured[:, :3, 3]
    return [np.sum((np.asarray(out[k]["held_out_positions_m"])[test] * 1e3 - meas[test]) ** 2, axis=1)
            for k, test in enumerate(folds)]
