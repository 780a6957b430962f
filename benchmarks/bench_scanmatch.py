"""Scan matching on the Kümmerle benchmark logs: relations error (mean ± std, translation m and
rotation deg) of raw odometry, our ICP odometry (with the wheels, and from scans alone as
KISS-ICP) and KISS-ICP, and ms per scan of the matchers, in the same run. Skipped when
../shared/data is absent.

    python -m benchmarks.bench_scanmatch [--max-scans N] [--draws K]

``--draws K`` runs our ICP (both ways) K times more, each with its Huber kernel scale nudged
by k * 1e-12 (relative): a draw of the rounding, as another BLAS kernel or CPU would give. One run's
figure over a whole log can hinge on a few scans, so the spread of these draws is the
figure's error bar.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "slam-benchmark"
OUT = Path("bench-out")


def main(argv=None) -> int:
    from gatmo.datasets.metrics import relations_error
    from gatmo.datasets.relations import read_relations
    from gatmo.datasets.rosbag import RosBag
    from gatmo.scanmatch import IcpConfig, ScanMatchOdometry
    from gatmo.scanmatch.kiss import KissIcpBackend

    ap = argparse.ArgumentParser()
    ap.add_argument("--max-scans", type=int, default=None)
    ap.add_argument("--draws", type=int, default=0)
    args = ap.parse_args(argv or [])
    if not DATA.exists():
        print(f"{DATA} not found: real data absent, nothing to measure")
        return 0
    out = {}
    for name in ("mit-csail", "aces", "intel"):
        scans = list(RosBag(DATA / f"{name}.sort.bag"))[: args.max_scans]
        rel = read_relations(DATA / f"{name}.relations")
        t = np.array([s.stamp_s for s in scans])
        res = {"scans": len(scans)}
        odom = np.array([s.odom_pose_xytheta for s in scans])
        res["odometry"] = relations_error(t, odom, rel)
        for label, matcher in (("ours", ScanMatchOdometry(IcpConfig())),
                               ("ours_scans_alone",
                                ScanMatchOdometry(IcpConfig(use_odometry=False))),
                               ("kiss_icp", KissIcpBackend())):
            t0 = time.perf_counter()
            poses = np.array([matcher.register(s).pose_xytheta for s in scans])
            ms = (time.perf_counter() - t0) * 1e3 / len(scans)
            res[label] = dict(relations_error(t, poses, rel), ms_per_scan=ms,
                              rescued=matcher.stats.get("rescued", 0))
        for label, use_odometry in (("ours", True), ("ours_scans_alone", False)):
            every = [res[label]]
            for k in range(1, args.draws + 1):
                matcher = ScanMatchOdometry(IcpConfig(kernel_scale_m=0.05 * (1 + k * 1e-12),
                                                      use_odometry=use_odometry))
                every.append(relations_error(
                    t, np.array([matcher.register(s).pose_xytheta for s in scans]), rel))
            if args.draws:
                res[f"{label}_draws"] = {
                    key: {"median": float(np.median([d[key] for d in every])),
                          "min": float(min(d[key] for d in every)),
                          "max": float(max(d[key] for d in every))}
                    for key in ("trans_mean_m", "rot_mean_deg")} | {"n": len(every)}
        out[name] = res
        print(name, json.dumps(res), flush=True)
    OUT.mkdir(exist_ok=True)
    (OUT / "scanmatch.json").write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
