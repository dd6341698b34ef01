"""FIGAROH's geometric calibration of a data set that bench_core.py wrote, timed through its public
interface (``BaseCalibration``: ``initialize()`` then ``solve()``), and its predictions at held-out
joints. Runs in a benchmark-only environment that has FIGAROH (PyPI ``figaroh``), never in the
project's; bench_core.py starts it and reads the JSON it prints. Not part of the station.

    FIGAROH_PYTHON benchmarks/_figaroh_peer.py FOLDER REPEAT
"""

from __future__ import annotations

import json
import logging
import statistics
import sys
import time
import warnings
from pathlib import Path


def main() -> int:
    folder, repeat = Path(sys.argv[1]), int(sys.argv[2])
    warnings.simplefilter("ignore")
    logging.disable(logging.CRITICAL)
    import numpy as np

    # FIGAROH lives in the benchmark-only environment: no stubs, and not in the project's
    from figaroh.calibration.base_calibration import BaseCalibration  # type: ignore[import-not-found,unused-ignore]
    from figaroh.calibration.calibration_tools import calc_updated_fkm  # type: ignore[import-not-found,unused-ignore]
    from figaroh.tools.robot import load_robot  # type: ignore[import-not-found,unused-ignore]

    class Calibration(BaseCalibration):
        """FIGAROH's default cost (SE(3) log map), as its public interface gives it; the frames of
        the measuring instrument (base) and of the measured tool (tip) are unknown, as the
        station's set-up R and tool K are."""

        def load_param(self, config_file, setting_type="calibration"):
            super().load_param(config_file, setting_type)
            self.calib_config["known_baseframe"] = False
            self.calib_config["known_tipframe"] = False

    robot = load_robot(str(folder / "robot.urdf"), load_by_urdf=True)
    out = {}
    for case in json.loads((folder / "cases.json").read_text()):
        config = str(folder / case["config"])

        def fit(config=config):
            cal = Calibration(robot, config)
            cal.initialize()
            cal.solve(enable_logging=False)
            return cal

        cal = fit()
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            fit()
            times.append(time.perf_counter() - t0)
        held = np.loadtxt(folder / case["held_out"], delimiter=",", ndmin=2)
        cfg = dict(cal.calib_config)
        cfg["NbSample"] = held.shape[0]
        q = np.tile(robot.q0, (held.shape[0], 1))
        q[:, cfg["config_idx"]] = held
        pee = calc_updated_fkm(robot.model, robot.data, cal.LM_result.x, q, cfg)
        n_meas = int(cfg["calibration_index"])
        pos = np.asarray(pee).reshape(n_meas, held.shape[0])[:3].T  # DOF-major rows x, y, z
        out[case["name"]] = {"median_s": statistics.median(times) if times else None,
                             "best_s": min(times) if times else None, "runs": repeat,
                             "held_out_positions_m": pos.tolist(), "parameters": int(len(cal.LM_result.x)),
                             "status": str(cal.STATUS)}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
