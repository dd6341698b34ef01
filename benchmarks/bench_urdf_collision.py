"""Time of the collision check (issue 40) with a URDF's own link shapes: the PUMA 560 example's robot
exported to URDF (examples/puma560), its upper arm and forearm given (a) no <collision> (the station's
capsules), (b) <cylinder>s, (c) STL meshes of trimesh capsules (``--triangles`` about that many each),
the same plan checked each way: poses, path samples, those evaluated, the least clearance, the
check's seconds (median of 3; the shapes built once before, as a run does).
Usage: python benchmarks/bench_urdf_collision.py [--triangles 2000]"""

from __future__ import annotations

import argparse
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from station.cell.config.cell_config import load_config
from station.cell.plan.collision import check_path
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.run_path import plan_path
from station.io.export.model_files import export_model
from station.io.robot.files import load_robot

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "puma560"
#: link, origin (xyz [m], rpy [rad]) of its body along the link, radius [m], length [m]: the upper arm
#: 431.8 mm along x of link_A2 (149.09 mm off along z), the forearm 433.07 mm along y of link_A3
LINKS = (("link_A2", "0.2159 0 0.149", "0 1.5707963267948966 0", 0.06, 0.4318),
         ("link_A3", "0.02032 0.2165 0", "1.5707963267948966 0 0", 0.05, 0.433))


def _cell(folder: Path, kind: str, triangles: int) -> Path:
    import trimesh

    text = export_model(load_robot(str(EXAMPLE / "puma560.mdh.csv")), "urdf", setup=False).text
    for link, xyz, rpy, r, length in LINKS if kind != "capsules" else ():
        if kind == "cylinders":
            geo = f'<cylinder radius="{r}" length="{length}"/>'
        else:
            count = max(4, int((triangles / 2) ** 0.5))
            trimesh.creation.capsule(height=length - 2 * r, radius=r, count=[count, count]).export(folder / f"{link}.stl")
            geo = f'<mesh filename="{link}.stl"/>'
        inside = f'<collision><origin xyz="{xyz}" rpy="{rpy}"/><geometry>{geo}</geometry></collision>'
        text = text.replace(f'<link name="{link}"/>', f'<link name="{link}">{inside}</link>')
    (folder / "puma.urdf").write_text(text, encoding="utf-8")
    for name in ("head.toml", "body.csv"):
        shutil.copy(EXAMPLE / name, folder / name)
    cell = (EXAMPLE / "cell.toml").read_text(encoding="utf-8").replace('"puma560.mdh.csv"', '"puma.urdf"')
    (folder / "cell.toml").write_text(cell, encoding="utf-8")
    return folder / "cell.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=int, default=2000, help="about this many triangles per link mesh")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("capsules", "cylinders", "meshes"):
            folder = Path(tmp) / kind
            folder.mkdir()
            cfg = load_config(_cell(folder, kind, args.triangles))
            poses = plan_path(cfg, build_plan(cfg))
            report = check_path(cfg, poses)  # builds the shapes (and a mesh's BVH) once
            times = []
            for _ in range(3):
                t0 = time.perf_counter()
                check_path(cfg, poses)
                times.append(time.perf_counter() - t0)
            tris = sum(len(g.faces) for g in cfg.robot_collision.geometry if g.kind == "mesh")
            least = "over 4 mm" if report.closest is None else f"{report.closest.clearance_mm:.1f} mm ({report.closest.a} ↔ {report.closest.b})"
            print(f"{kind:9s} ({tris} triangles): {report.poses} poses, {report.samples} samples, {report.evaluated} "
                  f"evaluated, clash {'none' if report.clash is None else report.clash.describe()}, least clearance "
                  f"{least}; check {statistics.median(times):.2f} s (median of 3)")


if __name__ == "__main__":
    main()
