"""``gatmo calibrate`` on the Kümmerle benchmark logs: AMCL's odometry alphas fitted on a log's
first half, then the static localizer over the whole log with AMCL's default alphas (0.2) and
with the fitted ones, scored on the second half only (the scans the fit never saw), over seeds.
Skipped when ../shared/data is absent.

    python -m benchmarks.bench_calibrate [--logs intel,aces,mit-csail] [--seeds 5] [--tag T]

The fit's reference is ``gatmo map build``'s pose graph on the bag (per scan; for ACES and MIT
CSAIL the one ``bench_real_compare`` built, for Intel built here), not the poses the runs are
scored against where there is a choice: Intel is scored against radish's gmapping poses. The
relations (independent ground truth) score every run. Two sensor models, each with both alpha
sets: the real preset's filter on AMCL's default likelihood field (``amcl``) and the real
preset's own sharp ``likelihood_field_prob`` (``sharp``; the static side of ``--preset real``).
Writes bench-out/calibrate<tag>.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.bench_real_compare import DATA, LOGS, _prepare
from benchmarks.bench_real_compare import OUT as COMPARE_OUT

OUT = Path("bench-out")


def reference(name: str) -> tuple[Path, float]:
    """(TUM reference at every scan, its stamp offset) to fit on: a pose graph of the bag."""
    if name != "intel":
        return COMPARE_OUT / name / "gt.tum", 0.0
    path = OUT / "calibrate" / "intel_build.tum"
    if not path.exists():
        from gatmo.pipeline.mapping import build_map

        path.parent.mkdir(parents=True, exist_ok=True)
        build_map(DATA / "slam-benchmark" / "intel.sort.bag", path.with_suffix(".yaml"),
                  poses_out=path)
    return path, 0.0


def score_second_half(poses_path: Path, gt_path: Path, relations, t_mid: float) -> dict:
    from gatmo.datasets.metrics import ate, relations_error
    from gatmo.datasets.tum import read_tum

    t, p = read_tum(poses_path)
    keep = t >= t_mid
    gt_t, gt_p = read_tum(gt_path)  # in the bag's clock (bench_real_compare._prepare)
    a = ate(t[keep], p[keep], gt_t, gt_p, max_dt_s=0.05)
    r = relations_error(t[keep], p[keep], relations, max_dt_s=0.002)
    return {"ate_rmse_m": a["rmse_m"], "ate_median_m": a["median_m"],
            "lost_fraction": a["lost_fraction"], "rel_trans_mean_m": r["trans_mean_m"],
            "rel_rot_mean_deg": r["rot_mean_deg"], "rel_used": r["n_used"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", default=",".join(LOGS))
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--tag", default="")
    args = ap.parse_args(argv or [])
    if not (DATA / "slam-benchmark").exists():
        print(f"skipped: {DATA} not found (the Kümmerle benchmark logs are needed)")
        return 0
    from gatmo.datasets.relations import read_relations
    from gatmo.pipeline.calibrate import calibrate_odometry
    from gatmo.pipeline.config import real_stack_config
    from gatmo.pipeline.localize import run_localize
    from gatmo.pipeline.runs import load_scans

    res: dict = {}
    work = OUT / "calibrate"
    work.mkdir(parents=True, exist_ok=True)
    for name in args.logs.split(","):
        log = DATA / "slam-benchmark" / f"{name}.sort.bag"
        map_yaml, gt, pose0 = _prepare(name, COMPARE_OUT / name)
        rel = read_relations(DATA / "slam-benchmark" / f"{name}.relations")
        stamps = np.array([s.stamp_s for s in load_scans(log)])
        half = len(stamps) // 2
        ref, offset = reference(name)
        models = {"amcl": real_stack_config(sharp_model=False).amcl,
                  "sharp": real_stack_config(sharp_model=True).amcl}
        entry: dict = {"scans": len(stamps), "fit_scans": half, "reference": str(ref)}
        fits: dict = {}  # one fit per odometry model and update thresholds
        for mname, base in models.items():
            key = (base.odom_model, base.update_min_d_m, base.update_min_a_rad)
            if key not in fits:
                fits[key] = calibrate_odometry(log, reference_path=ref, stamp_offset_s=offset,
                                               config=base, max_scans=half)
            fit = fits[key]
            entry[f"fit_{mname}"] = {k: fit[k] for k in (
                "alphas", "steps", "rejected", "z_std_current", "z_std_fitted", "z_std_holdout",
                "trans_scale", "rot_scale", "reference_noise_std")}
            fitted = base.model_copy(update={f"alpha{i + 1}": v
                                             for i, v in enumerate(fit["alphas"])})
            for aname, cfg in (("default", base), ("fitted", fitted)):
                rows = []
                for seed in range(args.seeds):
                    out = work / f"{name}_{mname}_{aname}_{seed}.tum"
                    run_localize(map_yaml, log, out_path=out, config=cfg, initial_pose=pose0,
                                 seed=seed, gt_path=gt)
                    rows.append(score_second_half(out, gt, rel, stamps[half]))
                    print(name, mname, aname, seed, {k: round(v, 4) for k, v in
                                                     rows[-1].items()}, flush=True)
                entry[f"{mname}_{aname}"] = {
                    k: float(np.mean([r[k] for r in rows])) for k in rows[0]} | {
                    "ate_rmse_m_per_seed": [r["ate_rmse_m"] for r in rows]}
        res[name] = entry
        (OUT / f"calibrate{args.tag}.json").write_text(json.dumps(res, indent=1))
    for name, e in res.items():
        for m in ("amcl", "sharp"):
            d, f = e[f"{m}_default"], e[f"{m}_fitted"]
            print(f"{name:10s} {m:6s} alphas {e[f'fit_{m}']['alphas']}: ATE "
                  f"{d['ate_rmse_m']:.3f} -> {f['ate_rmse_m']:.3f} m, lost "
                  f"{d['lost_fraction']:.3f} -> {f['lost_fraction']:.3f}, relations "
                  f"{d['rel_trans_mean_m']:.3f} -> {f['rel_trans_mean_m']:.3f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
