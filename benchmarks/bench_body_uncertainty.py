"""Cost of the calibration body's uncertainty in the identification (issue 8.3): identify with and
without body σ, and the sandwich alone, on pose data; medians of repeated runs after a warm-up.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_body_uncertainty.py [--repeat 7]

Prints each figure and the ratio with / without body σ. No asserts. On a loaded machine give
BLAS one thread: its threads contending for the cores make the small QRs 10–50× slower.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks._timing import median_time  # noqa: E402
from station.core.identification.identify import identify  # noqa: E402
from station.core.kinematics.poses import spread_joints  # noqa: E402
from station.core.measurement.measurements import add_body_error, add_noise, residuals_and_jacobian, synthetic_set  # noqa: E402
from station.core.measurement.uncertainty import body_sandwich, linear_uncertainty  # noqa: E402
from station.core.units import ARCSEC, UM  # noqa: E402
from station.io.robot.files import load_robot  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="timed runs per figure (>= 5)")
    args = ap.parse_args(argv)
    repeat = max(5, args.repeat)
    model = load_robot("sr800")
    rng = np.random.default_rng(0)
    true = model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), 5e-4, 0.1)
    for n_points, per_point in ((24, 6), (200, 5)):
        n = n_points * per_point
        q = spread_joints(model, n, rng)
        plain = synthetic_set(model, "pose", q, true)
        lever = rng.standard_normal((n, 3)) * 25.0
        body = plain.with_body(np.repeat(np.arange(n_points), per_point),
                               np.tile([20 * UM, 10 * ARCSEC], (n_points, 1)), lever)
        meas = add_noise(body, add_body_error(body, body.measured, rng), rng)
        plain, body = plain.with_measured(meas), body.with_measured(meas)
        res = identify(model, body)
        _, J = residuals_and_jacobian(model, body, res.params)
        fs = body.fit_sigma()
        Jw = J[:, res.chosen_index] / fs[:, None]
        t_plain = median_time(lambda: identify(model, plain), repeat)  # noqa: B023 - timed at once
        t_body = median_time(lambda: identify(model, body), repeat)  # noqa: B023
        t_lin = median_time(lambda: linear_uncertainty(Jw, res.chosen), repeat)  # noqa: B023
        t_sand = median_time(lambda: body_sandwich(Jw, res.chosen, body, fs), repeat)  # noqa: B023
        print(f"{n} poses at {n_points} body points:")
        print(f"  identify without body σ   {t_plain * 1e3:8.2f} ms")
        print(f"  identify with body σ      {t_body * 1e3:8.2f} ms   ({t_body / t_plain:.2f}×)")
        print(f"  linear_uncertainty alone  {t_lin * 1e3:8.3f} ms")
        print(f"  body_sandwich alone       {t_sand * 1e3:8.3f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
