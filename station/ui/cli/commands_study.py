"""``station study``: the chapter's §7.5 simulation studies (``station.core.accuracy.studies``), or with
``--model`` the error terms' σ-versus-scatter study (issue 30; ``docs/studies.md``)."""

from __future__ import annotations

from station.errors import ConfigError
from station.ui.cli.commands_core import _print_json, _robot


def _terms_study(args, model, n_sets: int) -> list | None:
    """``study --model``: the error terms' σ-versus-scatter study (issue 30), or None for the chapter's."""
    from station.ui.cli.commands_model import model_names

    names = model_names(getattr(args, "error_model", None))
    if names == ("geometric",):
        return None
    from station.core.accuracy.studies import terms_study
    from station.core.terms.selection import expand_families

    if any(n in ("drift", "backlash") for n in names):
        raise ConfigError("--model: drift and backlash describe a measurement run, not the robot; the study takes "
                          "compliance, cyclic, cyclic2 and cyclic.q<j>")
    families = expand_families(model, ("compliance", "cyclic") if names == ("auto",) else names)
    # the terms' Monte Carlo solves every set at once: 300 by default (the chapter studies' default 1000
    # would take 3 GB), or the --sets given
    sets = 100 if args.quick else (300 if args.sets == 1000 else args.sets)
    return [terms_study(model, families, n_sets=sets, seed=args.seed)]


def _progress():
    """Each study as it ends, on stderr (stdout stays the report or the JSON): a long --sets shows
    where it is."""
    import sys
    import time

    t0 = time.perf_counter()

    def show(done: int, total: int, report) -> None:
        print(f"study {done}/{total} done after {time.perf_counter() - t0:.1f} s: {report.name}", file=sys.stderr,
              flush=True)
    return show


def cmd_study(args) -> int:
    from station.core.accuracy.studies import chapter_studies

    model = _robot(args, args.robot)[0]  # random joints of the model: a joint map does not change them
    n_sets = min(args.sets, 200) if getattr(args, "quick", False) else args.sets
    if n_sets < 3:
        raise ConfigError(f"--sets must be at least 3 Monte Carlo data sets (got {n_sets}): give --sets 3 or "
                          f"more (1000 sets give each σ to about 2 %, 1/√(2N))")
    reports = _terms_study(args, model, n_sets) or chapter_studies(model, seed=args.seed, n_sets=n_sets,
                                                                   progress=_progress())
    if args.json:
        _print_json({"robot": model.name, "seed": args.seed, "monte_carlo_sets": n_sets,
                     "studies": [{"study": r.name, "figures": r.numbers, "parameters": list(r.table),
                                  "chapter": {x.quantity: x.chapter for x in r.rows},
                                  "notes": list(r.notes)} for r in reports]})
        return 0
    for r in reports:
        print(f"\n== {r.name}")
        print(f"   {'quantity':44s} {'station':30s} chapter")
        for row in r.rows:
            print(f"   {row.quantity:44s} {row.station:30s} {row.chapter}")
        if r.table:
            print(f"   {'parameter':12s} {'σ linear':>12s} {'σ Monte Carlo':>14s} {'MC/linear':>10s}")
            for t in r.table:
                if "linear_sigma_um" in t:
                    lin, mc = f"{t['linear_sigma_um']:.1f} µm", f"{t['monte_carlo_sigma_um']:.1f} µm"
                elif "linear_sigma_arcsec" in t:
                    lin, mc = f"{t['linear_sigma_arcsec']:.1f}″", f"{t['monte_carlo_sigma_arcsec']:.1f}″"
                else:  # a term in its own unit (compliance: rad per N·m, or of the lumped gravity term)
                    lin, mc = f"{t['linear_sigma']:.3g}", f"{t['monte_carlo_sigma']:.3g}"
                print(f"   {t['parameter']:12s} {lin:>12s} {mc:>14s} {t['ratio_mc_linear']:10.2f}"
                      + (f"  [{t['unit']}]" if "unit" in t and "linear_sigma_arcsec" not in t else ""))
        for n in r.notes:
            print(f"   note: {n}")
    return 0
