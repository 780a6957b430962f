"""``gatmo compare`` on the real Kümmerle benchmark logs (issue 6, real data): the static
localizer vs the full stack, both with the same configuration and seed. People walk, doors open
and clutter comes and goes: GATMO must not make localization worse.

    python -m benchmarks.bench_real_compare [--logs intel,aces,mit-csail] [--max-scans N]
                                            [--demo-config] [--split K] [--alphas-from JSON]
                                            [--set KEY=VALUE ...] [--tag NAME]

Maps and reference poses:

* intel: map rendered from the gmapping-corrected log (``radish-corrected``), reference poses
  the corrected ones (intel stamps = corrected stamps + 976052857.33753 s, README of the data);
* aces, mit-csail: the corrected logs cannot be joined to the bags (ACES has no published time
  offset, the CSAIL log stores 6-digit stamps), so the map and reference poses come from
  ``gatmo map build`` on the bag itself (pose graph: 0.036 m / 0.031 m relations error). The
  relations (independent ground truth) score both sides either way.

Needs ../shared/data (skips with a message otherwise). Writes bench-out/real_compare/<log>/ and
bench-out/real_compare/figures.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
OUT = Path("bench-out") / "real_compare"
INTEL_SHIFT_S = 976052857.33753  # intel timestamps = corrected timestamps + this
KEYS = ("ate_rmse_m", "ate_median_m", "lost_fraction", "rel_trans_mean_m", "rel_rot_mean_deg",
        "ms_per_scan", "absent", "relocated", "added")


def real_log_config(demo_model: bool = False):
    """The configuration for the three logs (:func:`gatmo.pipeline.config.real_stack_config`;
    ``demo_model``: its sharp model with the anchor filter, the CLI's ``--preset real``)."""
    from gatmo.pipeline.config import real_stack_config

    return real_stack_config(sharp_model=demo_model)


def intel_reference_scans() -> list:
    """The bag's 13,631 scans with reference poses: the corrected log has one pose every 3 s
    (its FLASER pose, read as odometry); between two, the nearest one carried by the bag's
    wheel odometry (over at most 1.5 s, a centimetre or two)."""
    from gatmo.datasets.open import open_log
    from gatmo.geometry import compose, interpolate_poses, nearest_index, relative

    corrected = DATA / "radish-corrected" / "intel-corrected.log.gz"
    ref = list(open_log(corrected, skip_bad=True))
    ref_t = np.array([s.stamp_s for s in ref]) + INTEL_SHIFT_S
    ref_pose = np.array([s.gt_pose_xytheta if s.gt_pose_xytheta is not None
                         else s.odom_pose_xytheta for s in ref])
    scans = list(open_log(DATA / "slam-benchmark" / "intel.sort.bag", skip_bad=True))
    t = np.array([s.stamp_s for s in scans])
    odom = np.array([s.odom_pose_xytheta for s in scans])
    keep = (t >= ref_t[0]) & (t <= ref_t[-1])
    odom_at_ref = interpolate_poses(t, odom, ref_t)
    k = nearest_index(ref_t, t)
    out = []
    for i in np.flatnonzero(keep):
        s = scans[i]
        s.gt_pose_xytheta = compose(ref_pose[k[i]], relative(odom_at_ref[k[i]], odom[i]))
        out.append(s)
    return out


LOGS = ("intel", "aces", "mit-csail")


def stamp_shift_s(name: str) -> float:
    """What the log's stamps add to its reference poses' stamps [s] (Intel's corrected log
    counts from its start; the others' references come from the bag itself)."""
    return INTEL_SHIFT_S if name == "intel" else 0.0


def reference_scans(name: str) -> list:
    """The log's scans with reference poses: Intel's from the corrected log
    (:func:`intel_reference_scans`); ACES' and MIT CSAIL's the optimized poses of ``gatmo map
    build`` on the bag (``bench-out/real_compare/<name>/gt.tum``, written by this benchmark),
    one per scan. Stamps as in the bag."""
    if name == "intel":
        return intel_reference_scans()
    from gatmo.datasets.open import open_log
    from gatmo.datasets.tum import read_tum
    from gatmo.geometry import nearest_index

    gt = OUT / name / "gt.tum"
    if not gt.exists():
        raise FileNotFoundError(f"{gt}: run `python -m benchmarks.bench_real_compare --logs "
                                f"{name}` first")
    t_ref, poses = read_tum(gt)
    scans = list(open_log(DATA / "slam-benchmark" / f"{name}.sort.bag", skip_bad=True))
    t = np.array([s.stamp_s for s in scans])
    k = nearest_index(t_ref, t)
    out = []
    for i in np.flatnonzero(np.abs(t_ref[k] - t) < 1e-3):  # the map build's poses are per scan
        scans[i].gt_pose_xytheta = np.asarray(poses[k[i]], dtype=float)
        out.append(scans[i])
    return out


def split_log(k: int, out: Path) -> list[Path]:
    """The Intel log cut into ``k`` CARMEN logs of equal scan counts, with the reference poses
    (``intel_reference_scans``) as their true poses; cached in ``out``."""
    from gatmo.datasets.carmen import write_carmen

    paths = [out / f"intel_{i + 1}of{k}.clf.gz" for i in range(k)]
    if not all(p.exists() for p in paths):
        out.mkdir(parents=True, exist_ok=True)
        scans = intel_reference_scans()
        for p, part in zip(paths, np.array_split(np.arange(len(scans)), k), strict=True):
            write_carmen(p, [scans[i] for i in part])
    return paths


def _prepare(name: str, out: Path):
    """(map yaml, gt tum, initial pose) for one log, cached in ``out``."""
    from gatmo.datasets.open import open_log
    from gatmo.datasets.tum import write_tum
    from gatmo.pipeline.mapping import render_reference_map

    map_yaml, gt = out / "map.yaml", out / "gt.tum"
    if name == "intel":
        corrected = DATA / "radish-corrected" / "intel-corrected.log.gz"
        if not map_yaml.exists():
            render_reference_map(corrected, map_yaml)
        if not gt.exists():
            scans = list(open_log(corrected, skip_bad=True))
            stamps = np.array([s.stamp_s for s in scans]) + INTEL_SHIFT_S
            poses = np.array([s.gt_pose_xytheta if s.gt_pose_xytheta is not None
                              else s.odom_pose_xytheta for s in scans])
            write_tum(gt, stamps, poses)
        return map_yaml, gt, np.array([0.6, -0.03, -0.35])
    if not map_yaml.exists() or not gt.exists():
        from gatmo.pipeline.mapping import build_map

        build_map(DATA / "slam-benchmark" / f"{name}.sort.bag", map_yaml, poses_out=gt)
    return map_yaml, gt, np.zeros(3)


def main(argv=None) -> int:
    from benchmarks._overrides import add_override_args, with_overrides

    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", default="intel,aces,mit-csail")
    ap.add_argument("--max-scans", type=int, default=None)
    ap.add_argument("--split", type=int, default=1,
                    help="intel only: cut the log into this many runs in time, the object map "
                    "carried from run to run (results under <log>-split<K>)")
    ap.add_argument("--demo-config", action="store_true",
                    help="the demo's likelihood_field_prob (sigma_hit 0.1 m) instead; results "
                    "under <log>-demo")
    ap.add_argument("--alphas-from", type=Path, default=None,
                    help="bench_calibrate's JSON (e.g. bench-out/calibrate_66b.json): both sides "
                    "run the odometry alphas fitted to each log there")
    add_override_args(ap)
    args = ap.parse_args(argv or [])
    if not (DATA / "slam-benchmark").exists():
        print(f"skipped: {DATA} not found (the Kümmerle benchmark logs are needed)")
        return 0
    from gatmo.pipeline.runs import compare

    figures: dict = {}
    fig_path = OUT / "figures.json"
    if fig_path.exists():
        figures = json.loads(fig_path.read_text())
    names = args.logs.split(",")
    unknown = sorted(set(names) - set(LOGS))
    if unknown:
        ap.error(f"--logs: unknown log(s) {', '.join(unknown)}; choose from {', '.join(LOGS)}")
    for name in names:
        out = OUT / name
        out.mkdir(parents=True, exist_ok=True)
        map_yaml, gt, pose0 = _prepare(name, out)
        cfg = with_overrides(real_log_config(demo_model=args.demo_config), args.set)
        if args.alphas_from is not None:
            fitted = json.loads(args.alphas_from.read_text())[name]["fit_amcl"]["alphas"]
            for i, v in enumerate(fitted):
                setattr(cfg.amcl, f"alpha{i + 1}", v)
        key = (f"{name}-demo" if args.demo_config else name) + (
            f"-split{args.split}" if args.split > 1 else "") + args.tag
        logs, gts = [DATA / "slam-benchmark" / f"{name}.sort.bag"], [gt]
        if args.split > 1:
            if name != "intel":
                raise SystemExit("--split needs reference poses along the log: intel only")
            # each run starts at its first scan's reference pose (in the log), scored against
            # the corrected poses as the whole log is
            logs, pose0 = split_log(args.split, out / f"split{args.split}"), None
            gts = [gt] * len(logs)
        out = OUT / key
        res = compare(map_yaml, logs, out / "cmp", initial_pose=pose0, gt_paths=gts,
                      relations_path=DATA / "slam-benchmark" / f"{name}.relations",
                      max_scans=args.max_scans, pictures=True, config=cfg)
        figures[key] = {f"{r['side']} {r['log']}" if len(logs) > 1 else r["side"]:
                        {k: r.get(k) for k in KEYS} for r in res.rows
                        if len(logs) > 1 or r.get("log") != "all"}
        for side, r in figures[key].items():
            print(key, side, {k: round(v, 3) if isinstance(v, float) else v
                               for k, v in r.items()}, flush=True)
        fig_path.write_text(json.dumps(figures, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
