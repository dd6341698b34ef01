"""The model chosen by the data (issue 30, ``--model auto``): which error terms beyond geometry earn
their place, by cross-validation and a paired test.

Scoring. Every candidate model (the geometry plus some families of
:mod:`station.core.terms.error_model`) is fitted to all data (:func:`station.core.terms.fit.fit_terms`)
and scored by cross-validation over the measurements: leave-one-out up to :data:`LOO_MAX` poses,
else :data:`K_FOLDS`-fold with one seeded assignment shared by every candidate (so that the errors
are paired pose by pose). A fold's refit is one Gauss–Newton step from the all-data solution on
the remaining poses (exact for the model linearised there; the terms are linear in their
parameters and the geometry barely curves over a fold's change), and its held-out error is the
position error [mm] of each left-out pose. The CV RMS is the RMS over all poses of those held-out
errors.

Selection (physics first, then evidence; forward, family by family). The candidates come in the
tiers of :func:`station.core.terms.physics_order.candidate_tiers`: gravity compliance; backlash and
drift where the rows carry approach sides and time; the harmonics of the joints the data move over
150° of their cycle angle (a joint's second harmonic once its first is in). From the
geometric model, each step tries every family of the current tier not yet in the model; a step where
none passes moves to the next tier. A candidate passes when a
one-sided bootstrap of the CV gain (the per-pose held-out squared errors paired against the current
model, :data:`N_BOOT` seeded resamples of the poses; issue 38: a rank test counted the poses and
missed a term that cuts the error of the few poses it loads) gives p < :data:`ALPHA` divided by the
number of evidence tiers times the number of candidates of that step (Bonferroni: picking among
many, or going on to the next tier after a miss, would otherwise keep a term by luck); compliance,
tried alone and first on physics, is held to :data:`ALPHA_PHYSICS` (family-wise 0.05 in all), and
so is the fitted torque shape (``mass_shape``, :mod:`station.core.terms.mass_shape`) that follows it
where the robot file gives no masses, on the σ-normalised squared held-out residuals of all the pose's rows (with pose data they hold the orientation, where wrist errors show first), their
mean is lower than the current model's, the CV position RMS (what the table reports) is below
the geometric model's, and no joint's fitted gravity deflection runs against its torque by more than
:data:`IMPLAUSIBLE_SIGMAS` σ (physically impossible: the joint would give against gravity; judged on
the joint's whole deflection, compliance and torque shape together, :func:`_plausible`). Where the
lumped compliance earned its place but came out so, the shape is tried with it in the next step at
the same level (the lumped shape, not gravity, is what is wrong). The step keeps the passing candidate with the lowest normalised CV error;
none passing in the last tier ends the selection. Nothing kept: the geometric model, and it says so. The chosen model
is never worse than the geometric one on the CV position error.

Assessment. The CV RMS of the chosen model is the one that chose it, and so is optimistic;
:func:`nested_cv` repeats the whole selection inside each outer training set and scores the chosen
model on the held-out poses (nested cross-validation), against the geometric fit of the same
training set.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from station.core.identification.identify import IdentificationResult, identify
from station.core.kinematics.model import RobotModel
from station.core.measurement.measurements import MeasurementSet
from station.core.terms.error_model import TermBasis, TermRows, TermSpec, available_families, term_basis
from station.core.terms.fit import TermFit, fit_terms
from station.core.terms.physics_order import candidate_tiers
from station.core.terms.term_size import RobotClass, TermSize, robot_class, term_sizes
from station.core.units import UM
from station.errors import ConfigError, IdentificationError

__all__ = ["ALPHA", "ALPHA_PHYSICS", "IMPLAUSIBLE_SIGMAS", "N_BOOT", "CandidateScore", "Selection", "select_model", "fit_model", "cv_errors", "nested_cv",
           "NestedCV", "held_out_e2", "columns_of", "all_terms_basis", "expand_families"]

#: the paired test's level for the terms tried on evidence alone (backlash, drift, harmonics), shared
#: by their tiers and a step's candidates (Bonferroni)
ALPHA = 0.01
#: the level of gravity compliance, the term tried first on physics (issue 38): every serial arm
#: bends under its weight, and a false drop costs a heavy arm ~40 % of its accuracy where a false
#: keep costs a few parameters' variance. On the FANUC R-2000iC its CV gain sits in the two poses
#: at the ends of the J2/J3 sweep, so in one 29-pose training set of five the bootstrap's p lies
#: between 0.01 and 0.04 although the gain is 30-50 %. The family-wise level of the whole selection
#: is ALPHA_PHYSICS + ALPHA = 0.05.
ALPHA_PHYSICS = 0.04
#: a compliance more than this many σ below zero is physically impossible (the joint would give
#: against gravity's pull); the candidate is not kept. On the UR10e camera set (4.4 mm scatter) the
#: three training sets of 200 where compliance passed its test had J3's at -3.3 to -9.5 σ, and held
#: out 10-30 % worse than the geometric fit
IMPLAUSIBLE_SIGMAS = 2.0
LOO_MAX = 40
K_FOLDS = 10


@dataclass(frozen=True)
class CandidateScore:
    """One row of the selection table: the model (``families`` added to the geometry), its number of
    fitted parameters, CV RMS [mm], change against the geometric model [%], the paired test's p
    against ``base`` (the model it extends; None for the geometric model), and whether it was kept."""

    families: tuple[str, ...]
    n_parameters: int
    cv_rms_mm: float
    change_pct: float
    p_value: float | None
    base: tuple[str, ...]
    kept: bool
    #: the level its p had to be under (alpha over the candidates of its step; None: not tested)
    level: float | None = None
    #: False where a term came out physically impossible (a joint's gravity deflection against its
    #: torque by more than :data:`IMPLAUSIBLE_SIGMAS` σ: it gives against gravity); such a candidate is not kept
    plausible: bool = True

    @property
    def label(self) -> str:
        return "geometric" if not self.families else "geometric + " + " + ".join(self.families)

    def to_dict(self) -> dict:
        return {"model": self.label, "terms": list(self.families), "parameters": self.n_parameters,
                "cv_rms_um": self.cv_rms_mm / UM, "change_pct": self.change_pct, "p_value": self.p_value,
                "against": "geometric" if not self.base else " + ".join(self.base), "kept": self.kept,
                "level": self.level, "plausible": self.plausible}


@dataclass(frozen=True)
class Selection:
    """The outcome of :func:`select_model`: the ``chosen`` families (empty: geometric), the final
    fit on all data (``fit``), the geometric fit it started from, the ``table`` of every candidate
    scored, and how it was scored (``cv``: e.g. "leave-one-out", ``alpha``)."""

    chosen: tuple[str, ...]
    fit: TermFit
    geometric: IdentificationResult
    table: tuple[CandidateScore, ...]
    cv: str
    alpha: float
    forced: bool = False
    alpha_physics: float = ALPHA_PHYSICS
    #: the payload the robot file gives [kg] (None: none), for the robot's class (term_size)
    payload_kg: float | None = None

    @property
    def robot_class(self) -> RobotClass:
        return robot_class(self.fit.model, self.payload_kg)

    @property
    def sizes(self) -> tuple[TermSize, ...]:
        """The physical size of every kept joint term with σ, judged against the robot's class
        (:mod:`station.core.terms.term_size`)."""
        return term_sizes(self.fit, self.robot_class) if self.fit.basis.size else ()

    @property
    def summary(self) -> str:
        if self.forced:
            return ("model forced: geometric" if not self.chosen else
                    f"model forced: geometric + {' + '.join(self.chosen)}" + self.sizes_text)
        if not self.chosen:
            near = self.closest
            why = "" if near is None else (
                f"; closest: {near.label}, {self.cv} RMS {near.cv_rms_mm / UM:.1f} µm ({near.change_pct:+.1f} %), "
                f"p {near.p_value:.3g} where {self.level_of(near):.2g} was needed"
                + ("" if near.plausible else ", and a compliance came out negative (a joint giving against gravity)"))
            return "no term beyond geometry earned its place: the result is the geometric fit" + why
        geo = self.table[0].cv_rms_mm
        best = next(r for r in self.table if r.families == self.chosen and r.kept).cv_rms_mm
        return (f"kept {' + '.join(self.chosen)}: {self.cv} RMS {best / UM:.1f} µm against the geometric "
                f"{geo / UM:.1f} µm ({100 * (best - geo) / geo:+.0f} %)" + self.sizes_text)

    @property
    def sizes_text(self) -> str:
        """'; sizes (…): joint 2 gravity sag: up to …' of the kept joint terms ('' without)."""
        sizes = self.sizes
        if not sizes:
            return ""
        rc = self.robot_class
        return (f"; sizes ({rc.name} arm, reach {rc.reach_mm / 1000:.2f} m): "
                + "; ".join(z.describe() for z in sizes))

    @property
    def step_candidates(self) -> int:
        """Candidates scored in the first step (the Bonferroni divisor there)."""
        return max(1, sum(1 for r in self.table if r.families and not r.base))

    def level_of(self, row: CandidateScore) -> float:
        """The level ``row``'s p had to be under (older selections: the first step's)."""
        return row.level if row.level is not None else self.alpha / self.step_candidates

    @property
    def closest(self) -> CandidateScore | None:
        """Where nothing beyond geometry was kept (and it was chosen, not forced): the candidate that
        came closest to being kept, the lowest p of the paired test (ties: the lower CV RMS); what
        the summary and the JSON name so that "nothing kept" says by how much."""
        if self.chosen or self.forced:
            return None
        scored = [r for r in self.table if r.families and r.p_value is not None]
        return min(scored, key=lambda r: (r.p_value, r.cv_rms_mm)) if scored else None

    def to_dict(self) -> dict:
        near = self.closest
        return {"chosen": list(self.chosen), "summary": self.summary, "cv": self.cv, "alpha": self.alpha,
                "alpha_physics": self.alpha_physics, "closest": None if near is None else {
                    **near.to_dict(), "level_needed": self.level_of(near)},
                "test": f"one-sided bootstrap ({N_BOOT} seeded resamples of the poses) of the mean paired difference of "
                        "the per-pose sums of σ-normalised squared held-out residuals against the model extended; kept: p below the row's level (compliance and its fitted torque shape, tried first on physics: alpha_physics; the "
                        "other terms: alpha over their tiers and the step's candidates), "
                        "their mean lower, the CV position RMS below the geometric model's, and no joint's gravity "
                        f"deflection (compliance and torque shape) against its torque by more than {IMPLAUSIBLE_SIGMAS:g} σ",
                "table": [r.to_dict() for r in self.table], "terms": self.fit.terms_dict(),
                "robot_class": self.robot_class.to_dict(), "term_sizes": [z.to_dict() for z in self.sizes],
                "dropped_terms": list(self.fit.dropped),
                "identifiability": [t.to_dict() for t in self.fit.identifiability],
                "units": {"cv_rms_um": "µm", "change_pct": "%", "value": "as each term's unit",
                          "sigma": "as each term's unit"}}


def columns_of(names: tuple[str, ...], families: tuple[str, ...]) -> np.ndarray:
    """Indices of the term names that belong to ``families``: ``cyclic.qj`` holds the first harmonic
    of joint j, ``cyclic2.qj`` the first and second."""
    out = []
    for i, n in enumerate(names):
        head, _, rest = n.partition(".")
        for fam in families:
            fh, _, fj = fam.partition(".")
            if head == "cyclic":
                joint, _, h = rest.partition(".")
                if (fh == "cyclic" and fj == joint and h.endswith("1")) or (fh == "cyclic2" and fj == joint):
                    out.append(i)
                    break
            elif fh == head:
                out.append(i)
                break
    return np.array(out, dtype=int)


def all_terms_basis(model: RobotModel, data: MeasurementSet, rows: TermRows | None, spec: TermSpec,
                    params=None) -> TermBasis:
    """Every candidate family's terms at the data's rows (first and second harmonics of every revolute
    joint, compliance, drift, backlash where the data say the approach); the gravity torques at the
    geometry ``params`` (the geometric fit's: the identified model that will carry the terms, whose
    tool may lie far from the robot file's; default the nominal)."""
    fams = [f.replace("cyclic.", "cyclic2.") for f in available_families(model, rows)]
    if spec.gravity.lumped:  # no masses in the robot file: the torque shape may be fitted (issue 38)
        fams.insert(fams.index("compliance") + 1, "mass_shape")
    return term_basis(model, data.joints, TermSpec(tuple(fams), spec.gravity, spec.ratios), rows, params=params)


def _folds(n: int, seed: int = 0) -> tuple[list[np.ndarray], str]:
    if n <= LOO_MAX:
        return [np.array([i]) for i in range(n)], "leave-one-out"
    perm = np.random.default_rng(seed).permutation(n)
    return [np.sort(f) for f in np.array_split(perm, K_FOLDS)], f"{K_FOLDS}-fold"


def cv_errors(fit: TermFit, folds: list[np.ndarray], weighted: bool = False) -> np.ndarray:
    """``(n_items,)`` held-out squared position error [mm²] of every pose (``weighted``: the sum of
    the squared σ-normalised held-out residuals of all the pose's rows, orientation included): each
    fold refitted by one Gauss–Newton step from the all-data solution without it (normal equations,
    σ-scaled columns)."""
    Jw, rw, w = fit.jacobian_w, fit.residuals_w, fit.weights
    rpi = fit.residuals.shape[1]
    scale = np.maximum(np.linalg.norm(Jw, axis=0), 1e-300)
    Js = Jw / scale
    A = Js.T @ Js
    b = Js.T @ rw
    out = np.empty(fit.residuals.shape[0])
    for f in folds:
        rows = (f[:, None] * rpi + np.arange(rpi)).ravel()
        Jf, rf = Js[rows], rw[rows]
        step = np.linalg.lstsq(A - Jf.T @ Jf, -(b - Jf.T @ rf), rcond=1e-12)[0]
        held_w = rf + Jf @ step  # σ-normalised held-out residuals
        if weighted:
            out[f] = np.sum(held_w.reshape(len(f), rpi) ** 2, axis=1)
        else:
            held = (held_w / w[rows]).reshape(len(f), rpi)[:, :3]  # [mm]
            out[f] = np.sum(held**2, axis=1)
    return out


def _rms(e2: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e2)))


#: bootstrap resamples of the CV gain: the smallest p is 1/(N_BOOT + 1) = 2.5e-4, below the level of a
#: step of 8 candidates (0.01 / 8)
N_BOOT = 4000


def _paired_p(cand: np.ndarray, base: np.ndarray, seed: int = 0) -> float:
    """One-sided p that the candidate's mean held-out squared error is not below the base's: the
    share of seeded bootstrap resamples of the poses whose mean paired difference is ≥ 0. It weighs
    the held-out squared errors themselves, not their ranks: a term that cuts the error of the dozen
    poses that load it (compliance on a J2/J3 sweep) shows, where a rank test counts poses."""
    d = np.asarray(cand, dtype=float) - np.asarray(base, dtype=float)
    if not np.any(d != 0):
        return 1.0
    rng = np.random.default_rng(seed)
    means = d[rng.integers(0, d.size, (N_BOOT, d.size))].mean(axis=1)
    return float((np.count_nonzero(means >= 0) + 1) / (N_BOOT + 1))


def _plausible(fit: TermFit) -> bool:
    """Whether no loaded joint of ``fit`` gives against gravity by more than :data:`IMPLAUSIBLE_SIGMAS`
    σ: per joint with a compliance term, its gravity deflection over the data (the compliance and,
    where fitted, the torque shape's terms of that joint) projected on the joint's torque (the
    compliance column). Alone, that is the compliance's sign and σ. Beside ``mass_shape`` the
    compliance column is one point's mass and the sum of the others' (mass_shape's module), so its
    own value may lie below zero where the deflection follows gravity: on the simulated IRB 2600
    class arm (seed 1, 454 designed poses) J3's read -1.44e-3 ± 0.71e-3 in a fit that cut the CV
    error from 80 to 60 µm, and the shape the arm needs was refused."""
    names = fit.basis.names
    cov = np.asarray(fit.uncertainty.covariance)[len(fit.chosen_index):, len(fit.chosen_index):]
    for k, n in enumerate(names):
        if not n.startswith("compliance."):
            continue
        joint = n.split(".", 1)[1]
        j = int(joint[1:]) - 1
        cols = [i for i, c in enumerate(names) if c == n or c.startswith(f"mass_shape.{joint}.")]
        v = fit.basis.B[:, j, k] @ fit.basis.B[:, j, cols]  # Σ τ · (deflection per unit of each term)
        along = float(v @ fit.values[cols])
        sigma = float(np.sqrt(max(v @ cov[np.ix_(cols, cols)] @ v, 0.0)))
        if along + IMPLAUSIBLE_SIGMAS * sigma < 0:
            return False
    return True


def _extend(current: tuple[str, ...], fam: str) -> tuple[str, ...]:
    if fam.startswith("cyclic2."):
        return tuple(f for f in current if f != "cyclic." + fam.split(".", 1)[1]) + (fam,)
    if fam == "mass_shape" and "compliance" not in current:  # the shape carries its compliance along
        return current + ("compliance", fam)
    return current + (fam,)


def _step_candidates(tier: tuple[str, ...], current: tuple[str, ...], bent_shape: bool) -> list[str]:
    """The families a step tries: the tier's not yet in the model; the fitted torque shape only
    beside a compliance kept (alone, it is compliance and more), or with it where the lumped
    compliance earned its place but came out giving against gravity at some joint (``bent_shape``:
    the lumped shape, not gravity, is what is wrong; 400 random poses of the simulated IRB 2600
    class arm, seed 2: the lumped compliance refused so, the harmonics took what they could and the arm
    missed by 108 µm where its repeatability leaves 21); a harmonic's second beside its first."""
    cands = [f for f in tier if f not in current and (f != "mass_shape" or "compliance" in current or bent_shape)]
    if any(f.startswith("cyclic.") for f in tier):
        cands += [f"cyclic2.{f.split('.', 1)[1]}" for f in current if f.startswith("cyclic.")]
    return cands


def fit_model(model: RobotModel, data: MeasurementSet, geometric: IdentificationResult, basis_all: TermBasis,
              families: tuple[str, ...], start: TermFit | None = None) -> TermFit:
    """The geometric fit extended by ``families`` (columns of ``basis_all``), from ``start`` if given
    (a fit of fewer terms)."""
    return fit_terms(model, data, geometric, basis_all.select(columns_of(basis_all.names, families)), start=start)


def _both_sides(approach: np.ndarray) -> bool:
    """Whether some joint's approach sign changes between the rows ``(n, g)`` (backlash identifiable
    for it; :func:`~station.core.terms.error_model.term_basis` drops the joints whose sign does not)."""
    s = np.sign(np.asarray(approach, dtype=float))
    return bool(s.ndim == 2 and s.shape[0] > 1 and np.any(s.max(axis=0) != s.min(axis=0)))


def expand_families(model: RobotModel, names: tuple[str, ...], rows: TermRows | None = None) -> tuple[str, ...]:
    """``--model`` names to families: ``cyclic`` is the first harmonic of every revolute joint,
    ``cyclic2`` the first and second; ``compliance``, ``drift``, ``backlash`` and ``cyclic.q<j>`` as
    they are; ``geometric`` none."""
    out: list[str] = []
    revolute = [j + 1 for j, t in enumerate(model.joint_types) if t == "revolute"]
    for n in names:
        if n == "geometric":
            continue
        if n in ("cyclic", "cyclic2"):
            out.extend(f"{n}.q{j}" for j in revolute)
        elif n == "backlash" and (rows is None or rows.approach is None):
            raise ConfigError("--model backlash needs the approach direction of each joint in the data "
                              "(columns approach_1 … approach_g, ±1)")
        elif n == "backlash" and rows is not None and rows.approach is not None and not _both_sides(rows.approach):
            raise ConfigError("backlash: no joint arrived from both sides in these data (every approach sign is the "
                              "same in every row), so the lost motion merges with the joint zeros and cannot be "
                              "fitted; measure the poses from both sides, or leave backlash out")
        else:
            known = set(available_families(model, rows)) | {"backlash", "mass_shape"}
            known |= {f.replace("cyclic.", "cyclic2.") for f in known if f.startswith("cyclic.")}
            if n not in known:
                raise ConfigError(f"unknown error term {n!r}; terms are geometric, auto, compliance, mass_shape, cyclic, cyclic2, "
                                  f"cyclic.q<j> / cyclic2.q<j> of a revolute joint, drift, backlash")
            out.append(n)
    return tuple(dict.fromkeys(out))


def select_model(model: RobotModel, data: MeasurementSet, rows: TermRows | None = None, spec: TermSpec | None = None,
                 geometric: IdentificationResult | None = None, alpha: float = ALPHA,
                 force: tuple[str, ...] | None = None, basis_all: TermBasis | None = None,
                 max_steps: int = 12, alpha_physics: float = ALPHA_PHYSICS) -> Selection:
    """Choose (or, with ``force``, take) the error terms for ``data`` (see the module). ``geometric``:
    the geometric fit of the same data (default: :func:`identify` with its defaults); ``rows``: per
    row time and approach signs; ``spec``: gravity and gear ratios."""
    spec = TermSpec() if spec is None else spec
    payload = float(spec.gravity.payload_kg) or None
    if data.kind == "distance":
        raise ConfigError("model selection needs pose or position data; distances are fitted geometric only")
    geo = identify(model, data) if geometric is None else geometric
    basis_all = all_terms_basis(model, data, rows, spec, geo.params) if basis_all is None else basis_all
    folds, cv_name = _folds(data.n_items)
    base_fit = fit_model(model, data, geo, basis_all, ())
    base_e, base_w = cv_errors(base_fit, folds), cv_errors(base_fit, folds, weighted=True)
    geo_rms = _rms(base_e)
    table = [CandidateScore((), base_fit.n_parameters, geo_rms, 0.0, None, (), True)]
    if force is not None:
        fams = expand_families(model, force, rows)
        fit = fit_model(model, data, geo, basis_all, fams) if fams else base_fit
        e = cv_errors(fit, folds)
        if fams:
            table.append(CandidateScore(fams, fit.n_parameters, _rms(e), 100 * (_rms(e) - geo_rms) / geo_rms,
                                        _paired_p(cv_errors(fit, folds, weighted=True), base_w), (), True))
        return Selection(fams, fit, geo, tuple(table), cv_name, alpha, forced=True, payload_kg=payload)
    tiers = candidate_tiers(model, data.joints, rows, spec.ratios, lumped=spec.gravity.lumped)
    physics = (("compliance",), ("mass_shape",))
    current: tuple[str, ...] = ()
    cur_fit, cur_w = base_fit, base_w
    tier = 0
    bent_shape = False
    for _ in range(max_steps):
        if tier >= len(tiers):
            break
        scored = []
        for fam in _step_candidates(tiers[tier], current, bent_shape):
            fams = _extend(current, fam)
            try:
                fit = fit_model(model, data, geo, basis_all, fams, start=cur_fit)
            except IdentificationError:
                continue
            if fit.basis.size == cur_fit.basis.size:
                continue  # the family added nothing the data can tell from what is there
            e, ew = cv_errors(fit, folds), cv_errors(fit, folds, weighted=True)
            scored.append((fams, fit, e, ew, _paired_p(ew, cur_w), _plausible(fit)))
        evidence = sum(1 for t in tiers if t not in physics)
        level = (alpha_physics if tiers[tier] in physics else
                 alpha / (max(1, evidence) * max(1, len(scored))))  # Bonferroni over the tiers and candidates
        earned = [sc for sc in scored if sc[4] < level and np.mean(sc[3]) < np.mean(cur_w) and _rms(sc[2]) < geo_rms]
        passing = [sc for sc in earned if sc[5]]
        bent_shape = bent_shape or any(sc[0][-1] == "compliance" and not sc[5] for sc in earned)
        for fams, fit, e, _, p, ok in scored:
            table.append(CandidateScore(fams, fit.n_parameters, _rms(e), 100 * (_rms(e) - geo_rms) / geo_rms, p,
                                        current, False, level, ok))
        if not passing:
            tier += 1  # nothing more of this tier: the next (physics first, then evidence)
            continue
        fams, fit, _, ew, _, _ = min(passing, key=lambda sc: float(np.mean(sc[3])))
        table = [CandidateScore(r.families, r.n_parameters, r.cv_rms_mm, r.change_pct, r.p_value, r.base,
                                r.kept or r.families == fams, r.level, r.plausible) for r in table]
        current, cur_fit, cur_w = fams, fit, ew
    return Selection(current, cur_fit, geo, tuple(table), cv_name, alpha, alpha_physics=alpha_physics,
                     payload_kg=payload)


@dataclass(frozen=True)
class NestedCV:
    """Nested cross-validation: per pose the held-out squared position error [mm²] of the geometric
    fit and of the auto-selected model of its outer training set, and the families each outer fold
    chose."""

    geometric_e2: np.ndarray
    auto_e2: np.ndarray
    chosen: tuple[tuple[str, ...], ...]
    cv: str

    @property
    def geometric_rms_mm(self) -> float:
        return _rms(self.geometric_e2)

    @property
    def auto_rms_mm(self) -> float:
        return _rms(self.auto_e2)


def held_out_e2(model: RobotModel, data: MeasurementSet, fit: TermFit, basis_test: TermBasis) -> np.ndarray:
    """``(n,)`` squared position error [mm²] of the fit ``fit`` at held-out ``data`` (``basis_test``:
    every term's basis at its rows), by the nonlinear model."""
    from station.core.terms.error_model import apply_terms

    cols = [basis_test.names.index(n) for n in fit.basis.names]
    T = apply_terms(model, data.joints, fit.params, basis_test.select(np.array(cols, dtype=int)), fit.values)
    meas = data.measured[:, :3, 3] if data.kind == "pose" else data.measured
    return np.sum((T[:, :3, 3] - meas) ** 2, axis=1)


def nested_cv(model: RobotModel, data: MeasurementSet, rows: TermRows | None = None, spec: TermSpec | None = None,
              alpha: float = ALPHA, outer_folds: int | None = None, seed: int = 1,
              geometric_fit: Callable[[MeasurementSet], IdentificationResult] | None = None) -> NestedCV:
    """Nested cross-validation of ``--model auto`` against the geometric model: in every outer fold
    both are fitted (auto: selected by its own inner CV) on the training poses alone and scored on
    the held-out poses by the nonlinear model. ``outer_folds``: None → leave-one-out up to
    :data:`LOO_MAX` poses, else that many folds. ``geometric_fit``: how a training set's geometric
    fit is made (default :func:`identify` with its defaults; e.g. with ``tool_unknown=True``)."""
    fit_geo = (lambda d: identify(model, d)) if geometric_fit is None else geometric_fit
    spec = TermSpec() if spec is None else spec
    n = data.n_items
    if outer_folds is None and n <= LOO_MAX:
        folds, name = [np.array([i]) for i in range(n)], "leave-one-out"
    else:
        k = outer_folds or K_FOLDS
        perm = np.random.default_rng(seed).permutation(n)
        folds, name = [np.sort(f) for f in np.array_split(perm, k)], f"{k}-fold"
    geo_e2, auto_e2 = np.empty(n), np.empty(n)
    chosen = []
    for f in folds:
        train = np.setdiff1d(np.arange(n), f)
        d_train, d_test = data.subset(train), data.subset(f)
        geo = fit_geo(d_train)
        basis_all = all_terms_basis(model, data, rows, spec, geo.params)  # the training fit's geometry
        b_train, b_test = basis_all.subset(train), basis_all.subset(f)
        sel = select_model(model, d_train, rows, spec, geometric=geo, alpha=alpha, basis_all=b_train)
        geo_fit = fit_model(model, d_train, geo, b_train, ())
        geo_e2[f] = held_out_e2(model, d_test, geo_fit, b_test)
        auto_e2[f] = held_out_e2(model, d_test, sel.fit, b_test)
        chosen.append(sel.chosen)
    return NestedCV(geo_e2, auto_e2, tuple(chosen), name)
