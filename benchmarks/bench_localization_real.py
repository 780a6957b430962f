"""The localizer on real data (issue 3), skipped when ../shared/data is absent.

* uob-meeting: the Stage run ``simpath2.bag`` in ``meeting.yaml``, scored against Stage's
  absolute ground truth. Stage's frame is not the map's: map = 0.96462 x stage + (15.08, 15.26)
  (fitted, see ../shared/data/README.md), so the map is loaded with its resolution and origin
  rescaled into Stage's frame, and noise is added to the noise-free odometry (Thrun's model,
  alphas 0.05, 2 % scale bias).
* CMU Wean Hall: global localization (no initial pose) on robotdata1; there is no ground truth,
  so the figures are the heaviest cluster's spread and the fraction of returns the map explains
  at the estimate (near 1 when it follows the hallway).

    python -m benchmarks.bench_localization_real
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
OUT = Path("bench-out")


def uob() -> dict:
    from gatmo.datasets.rosbag import RosBag
    from gatmo.datasets.sim.config import OdomConfig
    from gatmo.datasets.sim.robot import sample_odometry
    from gatmo.localization import AmclConfig, MonteCarloLocalizer
    from gatmo.maps.grid import OccupancyGrid
    from gatmo.maps.io import load_map

    g = load_map(DATA / "uob-meeting" / "meeting.yaml")
    s, t = 0.96462, np.array([15.08, 15.26])
    origin = (np.array(g.origin_xytheta[:2]) - t) / s
    grid = OccupancyGrid(g.cells, g.resolution_m / s, (origin[0], origin[1], 0.0))
    scans = list(RosBag(DATA / "uob-meeting" / "simpath2.bag"))
    gt = np.array([x.gt_pose_xytheta for x in scans])
    odom = sample_odometry(gt, OdomConfig(), np.random.default_rng(0), scale_bias=(1.02, 0.99))
    cfg = AmclConfig(laser_model="likelihood_field_prob", sigma_hit_m=0.1, z_hit=0.95,
                     z_rand=0.05, alpha1=0.05, alpha2=0.05, alpha3=0.05, alpha4=0.05,
                     max_beams=60)
    loc = MonteCarloLocalizer.from_config(cfg, grid, np.random.default_rng(0))
    loc.set_initial_pose(gt[0])
    t0 = time.perf_counter()
    est = np.array([loc.update(o, x).pose_xytheta for o, x in zip(odom, scans, strict=True)])
    secs = time.perf_counter() - t0
    err = np.hypot(*(est[:, :2] - gt[:, :2]).T)
    from gatmo.geometry import compose, relative

    dr = compose(gt[0], relative(odom[0], odom))  # dead reckoning from the true start
    dead = np.hypot(*(dr[:, :2] - gt[:, :2]).T)
    return {"scans": len(scans), "ate_rmse_m": float(np.sqrt(np.mean(err**2))),
            "median_m": float(np.median(err)), "max_m": float(err.max()),
            "odometry_only_final_m": float(dead[-1]), "ms_per_scan": secs * 1e3 / len(scans)}


def wean() -> dict:
    from gatmo.datasets.wean import WeanLog, load_wean_map
    from gatmo.geometry import compose, transform_points
    from gatmo.localization import AmclConfig, MonteCarloLocalizer
    from gatmo.maps.likelihood import LikelihoodField

    grid = load_wean_map(DATA / "cmu-wean" / "wean.dat.gz")
    scans = list(WeanLog(DATA / "cmu-wean" / "robotdata1.log.gz"))
    cfg = AmclConfig(min_particles=2000, max_particles=40000, laser_model="likelihood_field",
                     z_hit=0.95, z_rand=0.05, alpha1=0.1, alpha2=0.1, alpha3=0.1, alpha4=0.1,
                     max_beams=60, update_min_d_m=0.1, update_min_a_rad=0.1)
    loc = MonteCarloLocalizer.from_config(cfg, grid, np.random.default_rng(0))
    loc.global_localization()
    field = LikelihoodField(grid, 2.0)
    explained, spread = [], []
    t0 = time.perf_counter()
    for x in scans:
        e = loc.update(x.odom_pose_xytheta, x)
        pts = transform_points(compose(e.pose_xytheta, x.laser_pose_xytheta),
                               x.points_laser_xy())
        explained.append(float(np.mean(field.distance_at(pts) < 0.2)) if len(pts) else 0.0)
        spread.append(float(np.sqrt(e.cov[0, 0] + e.cov[1, 1])))
    secs = time.perf_counter() - t0
    n = len(scans)
    last = slice(n // 2, n)
    return {"scans": n, "explained_second_half": float(np.mean(explained[last])),
            "explained_first_50": float(np.mean(explained[:50])),
            "spread_m_second_half": float(np.median(spread[last])),
            "final_particles": int(len(loc.particles)), "ms_per_scan": secs * 1e3 / n}


def main(argv=None) -> int:
    if not DATA.exists():
        print(f"{DATA} not found: real data absent, nothing to measure")
        return 0
    res = {"uob_meeting": uob(), "wean_global": wean()}
    print(json.dumps(res, indent=1))
    OUT.mkdir(exist_ok=True)
    (OUT / "localization_real.json").write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
