"""gatmo's localizer beside Nav2's AMCL core (the ``amcl`` package on PyPI: C++ bindings of
nav2_amcl, GPL, benchmark-only: ``pip install amcl``), same map, scans, odometry, particle
count (fixed: min = max) and beams. Reports median ms per filter update, beam evaluations per
second, and the position error against ground truth. Writes bench-out/localization.json.

    python -m benchmarks localization            # full grid
    python -m benchmarks.bench_localization --quick
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

OUT = Path("bench-out")


def _scenario(tmp: Path):
    from gatmo.datasets.carmen import CarmenLog
    from gatmo.datasets.sim import SimConfig, simulate_scenario
    from gatmo.maps.io import load_map

    cfg = SimConfig.for_preset("office")
    cfg.rearrange.move_prob = 0.0
    cfg.rearrange.shift_prob = 0.0
    cfg.rearrange.add_count = 0
    cfg.rearrange.remove_prob = 0.0
    cfg.people.count_per_run = 0
    cfg.robot.duration_s = 40.0
    scen = simulate_scenario(tmp, preset="office", runs=1, seed=7, config=cfg)
    return load_map(scen.map_yaml), list(CarmenLog(scen.logs[0]))


def run_ours(grid, scans, n, beams, model, max_updates):
    from gatmo.localization import AmclConfig, MonteCarloLocalizer

    cfg = AmclConfig(min_particles=n, max_particles=n, max_beams=beams, laser_model=model,
                     z_hit=0.95, z_rand=0.05, z_short=0.05, z_max=0.05, alpha1=0.05,
                     alpha2=0.05, alpha3=0.05, alpha4=0.05, update_min_d_m=0.0,
                     update_min_a_rad=0.0)
    loc = MonteCarloLocalizer.from_config(cfg, grid, np.random.default_rng(0))
    loc.set_initial_pose(scans[0].gt_pose_xytheta, np.diag([0.05, 0.05, 0.02]))
    loc.update(scans[0].odom_pose_xytheta, scans[0])  # JIT warm-up outside the timing
    errs, ms = [], []
    for s in scans[1 : max_updates + 1]:
        t = time.perf_counter()
        e = loc.update(s.odom_pose_xytheta, s)
        ms.append((time.perf_counter() - t) * 1e3)
        errs.append(np.hypot(*(e.pose_xytheta[:2] - s.gt_pose_xytheta[:2])))
    return np.median(ms), np.median(errs), n_beams_used(scans[1], beams)


def n_beams_used(scan, beams):
    step = max(1, (scan.num_beams - 1) // max(beams - 1, 1))
    return len(range(0, scan.num_beams, step))


def run_nav2(grid, scans, n, beams, max_updates):
    import amcl

    occ = amcl.create_occupancy_grid_from_list(grid.cells.tolist(), grid.resolution_m,
                                               grid.origin_xytheta[0], grid.origin_xytheta[1])
    f = amcl.AMCL(n, n, 0.0, 0.0, amcl.MotionParameters(0.05, 0.05, 0.05, 0.05, 0.05),
                  amcl.LaserParameters(0.95, 0.05, 0.05, 0.05, 0.2, 0.1, 0.0, beams),
                  "differential")
    f.set_map(occ)
    f.set_laser_pose(amcl.Vector3D(*scans[0].laser_pose_xytheta))
    f.set_initial_pose(amcl.Vector3D(*scans[0].gt_pose_xytheta),
                       amcl.create_diagonal_covariance(0.05, 0.05, 0.02))
    errs, ms = [], []
    for s in scans[1 : max_updates + 1]:
        ls = amcl.create_laser_scan_from_list(
            [[float(r), float(a)] for r, a in zip(s.ranges_m, s.angles_rad, strict=True)],
            s.range_max_m)
        t = time.perf_counter()
        f.update(ls, amcl.Vector3D(*s.odom_pose_xytheta))
        ms.append((time.perf_counter() - t) * 1e3)
        m = f.get_pose_mean()
        errs.append(np.hypot(m.x - s.gt_pose_xytheta[0], m.y - s.gt_pose_xytheta[1]))
    return np.median(ms), np.median(errs)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv or [])
    try:
        import amcl  # noqa: F401

        have_nav2 = True
    except ImportError:
        have_nav2 = False
        print("the 'amcl' package is not installed (pip install amcl): ours only")
    counts = [500, 2000] if args.quick else [500, 2000, 5000, 20000]
    beam_list = [30, 60] if args.quick else [30, 60, 180]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        grid, scans = _scenario(Path(tmp))
    for n in counts:
        for b in beam_list:
            upd = 60 if n <= 5000 else 20
            row = {"particles": n, "beams": b}
            ms, err, used = run_ours(grid, scans, n, b, "beam", upd)
            row.update(ours_beam_ms=ms, ours_beam_err_m=err,
                       ours_beam_evals_per_s=n * used / (ms / 1e3))
            ms, err, _ = run_ours(grid, scans, n, b, "likelihood_field", upd)
            row.update(ours_lf_ms=ms, ours_lf_err_m=err, ours_lf_evals_per_s=n * used / (ms / 1e3))
            if have_nav2:
                ms, err = run_nav2(grid, scans, n, b, upd)
                row.update(nav2_beam_ms=ms, nav2_beam_err_m=err,
                           speedup_beam=ms / row["ours_beam_ms"])
            rows.append(row)
            print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                           for k, v in row.items()), flush=True)
    OUT.mkdir(exist_ok=True)
    (OUT / "localization.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
