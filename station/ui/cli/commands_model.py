"""``station identify --model …`` (issue 30): the error terms beyond geometry, chosen by the data
(``auto``) or forced (``compliance``, ``cyclic``, ``compliance+cyclic.q2``, …), on top of the
geometric fit the command has made. The geometric fit itself is untouched; this module only adds
the model's table, terms and identifiability to what ``identify`` prints."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from station.core.units import UM

if TYPE_CHECKING:
    from station.io.robot.terms import StoredTerms


def model_names(text: str | None) -> tuple[str, ...]:
    """``--model`` as a tuple of names (``("geometric",)`` by default)."""
    if not text:
        return ("geometric",)
    return tuple(n.strip() for n in text.replace(",", "+").split("+") if n.strip())


def identify_terms(args, model, data, res, mf=None, jmap=None):
    """The :class:`~station.core.terms.selection.Selection` that ``--model`` asks for, or None for the
    geometric model (nothing more is computed). ``mf``: the measurement file, whose ``time`` and
    ``approach`` columns (where given) time the drift and give the backlash its sides (the approach
    signs turned by the joint map's signs)."""
    names = model_names(getattr(args, "error_model", None))
    if names == ("geometric",):
        return None
    if getattr(args, "loss", "linear") != "linear":
        from station.errors import ConfigError

        raise ConfigError(f"--model {'+'.join(names)} fits the error terms by least squares; with --loss "
                          f"{args.loss} give --model geometric (the robust fit has no error terms yet)")
    from station.core.terms.error_model import GravityModel, TermRows, TermSpec
    from station.core.terms.selection import select_model

    rows = None
    if mf is not None and (mf.time is not None or mf.approach is not None or mf.payload_kg is not None):
        approach = mf.approach
        if approach is not None and jmap is not None:
            approach = approach * np.asarray(jmap.sign, dtype=float)
        rows = TermRows(order=mf.time, approach=approach, payload_kg=mf.payload_kg)
    spec = TermSpec(gravity=gravity_of(getattr(args, "robot", None), model, getattr(args, "base_link", None),
                                       getattr(args, "tip_link", None)) or GravityModel(),
                    ratios=gear_ratios_of(getattr(args, "robot", None), model))
    if names == ("auto",):
        return select_model(model, data, rows=rows, spec=spec, geometric=res)
    return select_model(model, data, rows=rows, spec=spec, geometric=res, force=names)


def _fmt_value(unit: str, v: float) -> str:
    return f"{v:.4g} {unit}" if unit != "rad" else f"{v / np.radians(1 / 3600):.2f}″ ({v:.3g} rad)"


def print_terms(sel) -> None:
    """The selection table, the kept terms with σ and their identifiability, as text."""
    print(f"model: {sel.summary}")
    print(f"{'model':58s} {'params':>6s} {sel.cv + ' RMS':>22s} {'change':>8s} {'p':>10s}")
    for r in sel.table:
        p = "–" if r.p_value is None else f"{r.p_value:.2g}"
        mark = " kept" if r.kept and r.families else ""
        print(f"{r.label[:58]:58s} {r.n_parameters:6d} {r.cv_rms_mm / UM:19.1f} µm {r.change_pct:+7.1f}% {p:>10s}{mark}")
    if not sel.forced:
        print(f"(a term is kept when a one-sided bootstrap of the CV gain on the per-pose σ-normalised held-out "
              f"squared residuals gives p < {sel.alpha:g} / candidates of its step and the CV errors drop; "
              f"docs/error-terms.md)")
    fit = sel.fit
    if fit.basis.size:
        print(f"{'term':22s} {'value':>28s} {'σ':>12s}  unit")
        for t in fit.terms_dict():
            r, turn = t.get("readable", t), t.get("largest_joint_turn")
            print(f"{t['name']:22s} {r['value']:28.4g} {r['sigma']:12.2g}  {r['unit']}"
                  + ("" if turn is None else f"  (up to {turn['value']:.1f} ± {turn['sigma']:.1f}″ of the joint here)"))
        print(f"RMS position residual with the terms {fit.rms_position_mm() / UM:.1f} µm "
              f"(geometric {sel.geometric.rms_position_mm() / UM:.1f} µm); normalised {fit.rms_normalized:.3f}")
    for ti in fit.identifiability:
        corr = ", ".join(f"{a}~{b} {c:+.2f}" for a, b, c in ti.correlations)
        print(f"identifiability {ti.family}: rank {ti.rank} of {ti.size}, condition {ti.condition:.1f} "
              f"(geometry alone {ti.condition_geometric:.1f}); strongest: {corr or '–'}")
    if fit.dropped:
        print(f"terms left out (not separable from the geometry at these poses): {', '.join(fit.dropped)}")


def output_params(res, sel) -> np.ndarray:
    """The geometry ``identify --output`` writes: the geometric fit's, or, with terms kept, the
    geometry fitted together with them (the two belong together)."""
    if sel is None or not sel.fit.basis.size:
        return res.params
    return sel.fit.params


def terms_toml(sel, robot=None, model=None, base=None, tip=None, data=None, geometric=None) -> str:
    """The ``[error_terms]`` table of the kept terms for ``identify --output`` (none: ''), and the
    robot file's ``[gravity]`` (the terms were computed with it; '' without)."""
    from station.io.robot.terms import error_terms_toml, gears_toml, gravity_toml

    grav = (gravity_toml(gravity_of(robot, model, base, tip)) + gears_toml(gear_ratios_of(robot, model))
            if robot is not None and model is not None else "")
    if sel is None or not sel.fit.basis.size:
        return grav
    fit = sel.fit
    effect = None
    geo = None if geometric is None else geometric.params  # the geometric fit of the same data
    if data is not None and model is not None and geo is not None:
        # what a format without the terms loses where they were fitted: the full model against the
        # geometric fit of the same data (the terms' raw effect is mostly absorbed by the geometry)
        from station.core.kinematics.forward import forward
        from station.core.terms.error_model import apply_terms

        full = apply_terms(model, data.joints, fit.params, fit.basis, fit.values)[:, :3, 3]
        d = full - forward(model, data.joints, geo)[:, :3, 3]
        effect = float(np.sqrt(np.mean(np.sum(d**2, axis=1)))) / UM
    return error_terms_toml(sel.chosen, fit.basis.names, fit.values, fit.sigma, fit.basis.units, effect,
                            geo) + grav


def gear_ratios_of(path, model) -> tuple[float, ...] | None:
    """The robot file's ``[gears] ratios`` (the cyclic terms cycle with the motor angle), or None."""
    if path is None:
        return None
    from station.io.robot.terms import read_gear_ratios

    return read_gear_ratios(path, model.n_joints)


def gravity_of(path, model, base=None, tip=None):
    """The robot file's link masses (:class:`~station.core.terms.error_model.GravityModel`): a TOML file's
    ``[gravity]``, a URDF's ``<inertial>`` of the chain ``base`` … ``tip``; None without them."""
    if path is None:
        return None
    if str(path).endswith(".urdf"):
        from station.io.robot.urdf_inertial import urdf_gravity

        return urdf_gravity(path, base, tip)
    from station.io.robot.terms import read_gravity

    return read_gravity(path, model.n_joints)


def stored_terms(path) -> StoredTerms | None:
    """The ``[error_terms]`` of a robot file (None: none, or not a TOML file)."""
    from station.io.robot.terms import read_error_terms

    return read_error_terms(path)


def forward_with_terms(model, path, q, setup: bool) -> tuple[np.ndarray, list[str], StoredTerms | None]:
    """World←tool ``(n, 4, 4)`` of the robot file ``path``'s model at joints ``q`` with its stored
    error terms applied, the notes on what was left out, and the terms (None: the file has none)."""
    from station.core.kinematics.forward import forward
    from station.core.terms.error_model import apply_terms, prediction_basis

    terms = stored_terms(path)
    if terms is None or not terms.names:
        return forward(model, q, setup=setup), [], None
    basis, zeros = prediction_basis(model, q, terms.families, terms.names, gravity_of(path, model),
                                    gear_ratios_of(path, model))
    T = apply_terms(model, q, model.nominal, basis, np.asarray(terms.values), setup=setup)
    notes = [f"error terms applied: {', '.join(n for n in terms.names if n not in zeros)}"]
    if zeros:
        notes.append(f"left at zero: {', '.join(zeros)} (drift describes the measurement run; backlash needs the "
                     f"approach direction, the middle of the lost motion is taken)")
    return T, notes, terms


def lost_in_format(model, terms: StoredTerms | None, fmt: str, n_poses: int = 200, gravity=None,
                   ratios=None) -> str | None:
    """What a format without error terms loses: the RMS [µm] of the terms' effect on the tool
    position at ``n_poses`` poses spread over the workspace (seeded), or None when nothing is lost."""
    if terms is None or not terms.names or fmt == "toml":
        return None
    from station.core.kinematics.forward import forward
    from station.core.kinematics.poses import spread_joints
    from station.core.terms.error_model import apply_terms, prediction_basis

    q = spread_joints(model, n_poses, np.random.default_rng(30))
    basis, _ = prediction_basis(model, q, terms.families, terms.names, gravity, ratios)
    d = apply_terms(model, q, model.nominal, basis, np.asarray(terms.values))[:, :3, 3] - forward(model, q)[:, :3, 3]
    rms = float(np.sqrt(np.mean(np.sum(d**2, axis=1)))) / UM
    head = f"the error terms beyond geometry ({', '.join(terms.names)}) are not written in {fmt.upper()}"
    if terms.effect_on_fit_um is not None and terms.geometric_params is not None:
        return (f"{head}: it holds the geometric fit of the same data instead, which misses the full model by "
                f"{terms.effect_on_fit_um:.1f} µm RMS at the poses they were fitted on; export --format toml to keep "
                f"them")
    return (f"{head}: they move the tool by {rms:.1f} µm RMS over the workspace ({n_poses} poses spread over the "
            f"joint ranges); export --format toml to keep them")


def joint_delta_of(model, terms: StoredTerms, gravity=None, ratios=None):
    """``q ↦ Δq(q)`` ``(n, g)`` [rad, mm] of the stored terms (drift and backlash at zero)."""
    from station.core.terms.error_model import prediction_basis

    values = np.asarray(terms.values, dtype=float)

    def delta(q: np.ndarray) -> np.ndarray:
        return prediction_basis(model, q, terms.families, terms.names, gravity, ratios)[0].joint_delta(values)

    return delta
