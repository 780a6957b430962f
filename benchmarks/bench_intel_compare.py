"""``gatmo compare`` on the full Intel lab log (issue 6, real data): the static localizer vs the
full stack, on a map rendered from the gmapping-corrected log, scored against the corrected
poses (ATE) and the Kümmerle relations. People walk and doors open: GATMO must not make things
worse.

    python -m benchmarks.bench_intel_compare [--max-scans N]

Needs ../shared/data (skips with a message otherwise). Writes bench-out/intel_compare/.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
OUT = Path("bench-out") / "intel_compare"
SHIFT_S = 976052857.33753  # intel timestamps = corrected timestamps + this


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--max-scans", type=int, default=None)
    args = ap.parse_args(argv or [])
    corrected = DATA / "radish-corrected" / "intel-corrected.log.gz"
    bag = DATA / "slam-benchmark" / "intel.sort.bag"
    if not corrected.exists() or not bag.exists():
        print(f"skipped: {DATA} not found (the Intel logs are needed)")
        return 0
    from gatmo.datasets.open import open_log
    from gatmo.datasets.tum import write_tum
    from gatmo.pipeline.config import sim_stack_config
    from gatmo.pipeline.mapping import render_reference_map
    from gatmo.pipeline.runs import compare

    OUT.mkdir(parents=True, exist_ok=True)
    map_yaml = OUT / "map.yaml"
    if not map_yaml.exists():
        render_reference_map(corrected, map_yaml)
    scans = list(open_log(corrected, skip_bad=True))
    stamps = np.array([s.stamp_s for s in scans]) + SHIFT_S
    poses = np.array([s.gt_pose_xytheta if s.gt_pose_xytheta is not None else s.odom_pose_xytheta
                      for s in scans])
    write_tum(OUT / "gt.tum", stamps, poses)
    cfg = sim_stack_config()
    cfg.amcl.alpha1 = cfg.amcl.alpha2 = cfg.amcl.alpha3 = cfg.amcl.alpha4 = 0.2
    res = compare(map_yaml, [bag], OUT / "cmp", initial_pose=np.array([0.6, -0.03, -0.35]),
                  gt_paths=[OUT / "gt.tum"],
                  relations_path=DATA / "slam-benchmark" / "intel.relations",
                  max_scans=args.max_scans, pictures=True, config=cfg)
    keys = ("ate_rmse_m", "ate_median_m", "lost_fraction", "rel_trans_mean_m",
            "rel_rot_mean_deg", "ms_per_scan", "absent", "relocated", "added")
    for r in res.rows:
        print(r["side"], {k: round(r[k], 3) if isinstance(r.get(k), float) else r.get(k)
                          for k in keys})
    (OUT / "figures.json").write_text(json.dumps(res.rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
