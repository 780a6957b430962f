"""gatmo's localizer beside Nav2's AMCL core (the ``amcl`` package on PyPI: C++ bindings of
nav2_amcl, GPL, benchmark-only: ``pip install amcl``; it has Nav2's beam model only), same map,
scans, odometry, particle count (fixed: min = max) and beams.

Per (particles, beams): Nav2's beam model, ours with the exact ray caster (``march``: jumps on the
distance transform, cell walk near obstacles), ours with the approximate range table (``lut``,
360 heading bins) and our likelihood field, run interleaved ``--reps`` times on the same scans.
Reported: median ms per filter update (whole update: motion, sensor, resampling, estimate), the
ratio Nav2 / ours per repetition (median over repetitions; the ratio is what counts on a shared
machine), beam evaluations per second over the whole update and over the sensor model alone,
and the median position error against ground truth. Writes bench-out/localization.json.

    python -m benchmarks.bench_localization            # full grid (about 10 minutes, 2 cores)
    python -m benchmarks.bench_localization --quick    # 500/2000 x 30/60, one repetition
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

OUT = Path("bench-out")
MODELS = ("nav2_beam", "ours_march", "ours_lut", "ours_lf")


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


def _config(n, beams, model, ray_caster="march"):
    from gatmo.localization import AmclConfig

    return AmclConfig(min_particles=n, max_particles=n, max_beams=beams, laser_model=model,
                      beam_ray_caster=ray_caster,
                      z_hit=0.95, z_rand=0.05, z_short=0.05, z_max=0.05, sigma_hit_m=0.2,
                      lambda_short=0.1, alpha1=0.05, alpha2=0.05, alpha3=0.05, alpha4=0.05,
                      update_min_d_m=0.0, update_min_a_rad=0.0)


def run_ours(grid, scans, n, beams, model, max_updates, ray_caster="march"):
    """(median ms per update, median ms in the sensor model, median position error m, beams
    used per update, set-up s) of our localizer."""
    from gatmo.localization import MonteCarloLocalizer

    cfg = _config(n, beams, model, ray_caster)
    loc = MonteCarloLocalizer.from_config(cfg, grid, np.random.default_rng(0))
    sensor_ms = []
    weigh = loc.sensor.weigh

    def timed_weigh(*a, **k):
        t = time.perf_counter()
        out = weigh(*a, **k)
        sensor_ms.append((time.perf_counter() - t) * 1e3)
        return out

    loc.sensor.weigh = timed_weigh
    loc.set_initial_pose(scans[0].gt_pose_xytheta, np.diag([0.05, 0.05, 0.02]))
    t = time.perf_counter()
    loc.update(scans[0].odom_pose_xytheta, scans[0])  # tables and JIT outside the timing
    setup_s = time.perf_counter() - t
    sensor_ms.clear()
    errs, ms, used = [], [], []
    for s in scans[1 : max_updates + 1]:
        t = time.perf_counter()
        e = loc.update(s.odom_pose_xytheta, s)
        ms.append((time.perf_counter() - t) * 1e3)
        used.append(e.n_valid_beams)
        errs.append(np.hypot(*(e.pose_xytheta[:2] - s.gt_pose_xytheta[:2])))
    return np.median(ms), np.median(sensor_ms), np.median(errs), np.median(used), setup_s


def run_nav2(grid, scans, n, beams, max_updates):
    """(median ms per update, median position error m) of Nav2's AMCL core (beam model)."""
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


def measure(grid, scans, n, beams, reps, have_nav2):
    """One table row: every model ``reps`` times, interleaved; medians over repetitions."""
    upd = 60 if n <= 5000 else 20
    per = {m: [] for m in MODELS}
    for _ in range(reps):
        if have_nav2:
            per["nav2_beam"].append(run_nav2(grid, scans, n, beams, upd))
        per["ours_march"].append(run_ours(grid, scans, n, beams, "beam", upd, "march"))
        per["ours_lut"].append(run_ours(grid, scans, n, beams, "beam", upd, "lut"))
        per["ours_lf"].append(run_ours(grid, scans, n, beams, "likelihood_field", upd))
    row = {"particles": n, "beams": beams, "updates": upd, "reps": reps}
    for m in ("ours_march", "ours_lut", "ours_lf"):
        r = np.array([x[:4] for x in per[m]])
        ms, sens, err, used = np.median(r, axis=0)
        row.update({f"{m}_ms": ms, f"{m}_sensor_ms": sens, f"{m}_err_m": err,
                    f"{m}_evals_per_s": n * used / (ms / 1e3),
                    f"{m}_sensor_evals_per_s": n * used / (sens / 1e3),
                    f"{m}_setup_s": float(np.median([x[4] for x in per[m]]))})
        row["beams_used"] = int(used)
    if have_nav2:
        r = np.array(per["nav2_beam"])
        row.update(nav2_beam_ms=float(np.median(r[:, 0])),
                   nav2_beam_err_m=float(np.median(r[:, 1])),
                   nav2_beam_evals_per_s=n * row["beams_used"] / (np.median(r[:, 0]) / 1e3))
        for m in ("ours_march", "ours_lut"):
            ratios = [nv[0] / o[0] for nv, o in zip(per["nav2_beam"], per[m], strict=True)]
            row[f"speedup_{m}"] = float(np.median(ratios))
    return row


def markdown(rows) -> str:
    head = ("| particles | beams | Nav2 beam ms | ours beam exact ms | ratio | ours beam LUT ms | "
            "ratio | ours LF ms | err m Nav2 / exact / LUT / LF | M beam evals/s exact / LUT / LF "
            "(whole update) | M evals/s sensor only exact / LUT / LF |")
    lines = [head, "|" + "---|" * 11]
    for r in rows:
        def g(k, fmt="{:.2f}", r=r):
            return fmt.format(r[k]) if k in r else "-"

        lines.append(
            f"| {r['particles']} | {r['beams_used']} | {g('nav2_beam_ms')} | "
            f"{g('ours_march_ms')} | {g('speedup_ours_march')} | {g('ours_lut_ms')} | "
            f"{g('speedup_ours_lut')} | {g('ours_lf_ms')} | "
            f"{g('nav2_beam_err_m', '{:.3f}')} / {g('ours_march_err_m', '{:.3f}')} / "
            f"{g('ours_lut_err_m', '{:.3f}')} / {g('ours_lf_err_m', '{:.3f}')} | "
            + " / ".join(f"{r[f'{m}_evals_per_s'] / 1e6:.0f}"
                         for m in ("ours_march", "ours_lut", "ours_lf")) + " | "
            + " / ".join(f"{r[f'{m}_sensor_evals_per_s'] / 1e6:.0f}"
                         for m in ("ours_march", "ours_lut", "ours_lf")) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--reps", type=int, default=None, help="repetitions (default 3; quick 1)")
    ap.add_argument("--particles", type=int, nargs="*", default=None)
    ap.add_argument("--beams", type=int, nargs="*", default=None)
    args = ap.parse_args(argv or [])
    try:
        import amcl  # noqa: F401

        have_nav2 = True
    except ImportError:
        have_nav2 = False
        print("the 'amcl' package is not installed (pip install amcl): ours only")
    counts = args.particles or ([500, 2000] if args.quick else [500, 2000, 5000, 20000])
    beam_list = args.beams or ([30, 60] if args.quick else [30, 60, 180])
    reps = args.reps or (1 if args.quick else 3)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        grid, scans = _scenario(Path(tmp))
    load0 = os.getloadavg()[0]
    for n in counts:
        for b in beam_list:
            row = measure(grid, scans, n, b, reps, have_nav2)
            rows.append(row)
            print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                           for k, v in row.items()), flush=True)
    print(markdown(rows))
    print(f"load average (1 min) at start / end: {load0:.2f} / {os.getloadavg()[0]:.2f}")
    OUT.mkdir(exist_ok=True)
    (OUT / "localization.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
