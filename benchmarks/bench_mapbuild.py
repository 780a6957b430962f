"""Map building on the Kümmerle benchmark logs (intel, aces, mit-csail): relations error
(mean ± std, translation m and rotation deg) of raw odometry, our ICP odometry and the
optimized pose graph, closures and seconds; the Intel map as a PNG. Skipped when
../shared/data is absent.

    python -m benchmarks.bench_mapbuild [--logs intel,aces,mit-csail] [--max-scans N]
                                        [--scans-alone]

``--scans-alone`` builds without the wheels (``icp.use_odometry: false``, what ``gatmo map
build --no-odometry`` and a laser-only bag do) and writes bench-out/mapbuild_scans_alone.json.
Writes bench-out/mapbuild.json and bench-out/intel_map.png. Reference (README of the data):
the gmapping-corrected Intel log scores 0.043 m / 0.70 deg on the 40 relations it covers.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "slam-benchmark"
OUT = Path("bench-out")


def _fmt(e: dict) -> str:
    return (f"{e['trans_mean_m']:.3f} ± {e['trans_std_m']:.3f} m  "
            f"{e['rot_mean_deg']:.2f} ± {e['rot_std_deg']:.2f} deg")


def _png(grid, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    img = np.where(grid.cells == 100, 0, np.where(grid.cells == 0, 255, 200)).astype(np.uint8)
    rows, cols = np.nonzero(img != 200)
    img = img[rows.min():rows.max() + 1, cols.min():cols.max() + 1]
    h, w = img.shape
    fig = plt.figure(figsize=(w / 100, h / 100), dpi=100)
    fig.figimage(img[::-1], cmap="gray", vmin=0, vmax=255)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _vs_gmapping(t, poses, rel) -> dict | None:
    """Ours and the gmapping-corrected Intel log on the relations the latter covers."""
    from gatmo.datasets.metrics import relations_error
    from gatmo.datasets.open import open_log
    from gatmo.datasets.relations import Relations
    from gatmo.geometry import nearest_index

    path = DATA.parent / "radish-corrected" / "intel-corrected.log.gz"
    if not path.exists():
        return None
    ref = [s for s in open_log(path, pose_is_reference=True, skip_bad=True)
           if s.gt_pose_xytheta is not None]
    rt = np.array([s.stamp_s for s in ref]) + 976052857.33753  # README of the data
    rp = np.array([s.gt_pose_xytheta for s in ref])

    def covered(q):
        return np.abs(rt[nearest_index(rt, q)] - q) <= 0.002

    m = covered(np.asarray(rel.t1_s)) & covered(np.asarray(rel.t2_s))
    sub = Relations(np.asarray(rel.t1_s)[m], np.asarray(rel.t2_s)[m],
                    np.asarray(rel.rel_xytheta)[m])
    return {"gmapping": relations_error(rt, rp, sub), "ours": relations_error(t, poses, sub)}


def main(argv=None) -> int:
    from gatmo.datasets.metrics import relations_error
    from gatmo.datasets.relations import read_relations
    from gatmo.datasets.rosbag import RosBag
    from gatmo.maps.mapping import render_map
    from gatmo.pipeline.mapping import build_trajectory
    from gatmo.scanmatch import IcpConfig

    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", default="intel,aces,mit-csail")
    ap.add_argument("--max-scans", type=int, default=None)
    ap.add_argument("--scans-alone", action="store_true")
    args = ap.parse_args(argv or [])
    icp_cfg = IcpConfig(use_odometry=not args.scans_alone)
    suffix = "_scans_alone" if args.scans_alone else ""
    if not DATA.exists():
        print(f"{DATA} not found: real data absent, nothing to measure")
        return 0
    OUT.mkdir(exist_ok=True)
    out = {}
    for name in args.logs.split(","):
        t0 = time.perf_counter()
        scans = list(RosBag(DATA / f"{name}.sort.bag"))[: args.max_scans]
        t_read = time.perf_counter() - t0
        rel = read_relations(DATA / f"{name}.relations")
        t = np.array([s.stamp_s for s in scans])
        t0 = time.perf_counter()
        icp, opt, res, odo_stats = build_trajectory(scans, icp_cfg=icp_cfg)
        t_graph = time.perf_counter() - t0
        t0 = time.perf_counter()
        grid = render_map(scans, opt)
        t_render = time.perf_counter() - t0
        odom = np.array([s.odom_pose_xytheta for s in scans])
        r = {"scans": len(scans), "keyframes": len(res.keyframes),
             "odometry": relations_error(t, odom, rel),
             "icp_odometry": relations_error(t, icp, rel),
             "pose_graph": relations_error(t, opt, rel),
             "closures": {k: v for k, v in res.stats.items() if k != "attempt_log"},
             "few_point_scans": odo_stats.get("fallback_few_points", 0),
             "rescued_scans": odo_stats.get("rescued", 0),
             "seconds": {"read": round(t_read, 1), "odometry_and_graph": round(t_graph, 1),
                         "render": round(t_render, 1),
                         "total": round(t_read + t_graph + t_render, 1)}}
        out[name] = r
        print(f"{name}: {len(scans)} scans, {len(res.keyframes)} keyframes, "
              f"{len(res.closures)} closures, {r['seconds']['total']} s", flush=True)
        for k in ("odometry", "icp_odometry", "pose_graph"):
            print(f"  {k:13s} {_fmt(r[k])}  (n={r[k]['n_used']})", flush=True)
        if name == "intel":
            _png(grid, OUT / f"intel_map{suffix}.png")
            r["vs_gmapping"] = _vs_gmapping(t, opt, rel)
            if r["vs_gmapping"]:
                g = r["vs_gmapping"]
                print(f"  on the {g['gmapping']['n_used']} relations the gmapping-corrected log "
                      f"covers: gmapping {_fmt(g['gmapping'])}, ours {_fmt(g['ours'])}",
                      flush=True)
    (OUT / f"mapbuild{suffix}.json").write_text(json.dumps(out, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
