"""GATMO alone, fed ground-truth poses (no localization error), on simulated halls: for every
moved or shifted piece, whether the robot saw through its old place and saw it at its new place
(from the simulator's truth), and what GATMO made of it. Separates GATMO's own accuracy from
the localizer's.

    python -m benchmarks.bench_gatmo_oracle [--seeds 5] [--first-seed 100] [--procs 2]
        [--return-prob 0.3 --runs 6] [--set gatmo.prior_earlier_poses=false --tag _noprior]
        [--pose-noise 0.03,1.0] [--pose-source stack --error-band all|none|const|slow|mid|fast]

``--pose-noise XY_M,YAW_DEG``: the true poses with an error added, slowly varying as a
filter's is (per axis a first-order autoregressive series, correlation 0.95 from scan to scan,
of that standard deviation): how much pose error GATMO tolerates.

``--pose-source stack``: first the full stack runs the scenario (``gatmo compare``'s full-stack
side, the object map carried over as usual); then GATMO starts afresh and is replayed on the
scans the stack trusted, at the true poses plus the stack's error in the band named by
``--error-band``: ``all`` (the stack's own poses), ``const`` (each run's median error),
``slow`` (its moving average over 101 scans), ``mid`` (15-scan minus 101-scan averages) or
``fast`` (the rest), and ``none`` (true poses, only the stack's choice of scans). Which kind of
localization error costs GATMO its finds, without the feedback loop.

Outcomes: found (right object, true pose), twin (at an identical piece's true pose: the map is
right, the identity swapped), wrong (relocated elsewhere), absent (noticed gone, not found),
missed. Observability: both / old / new / none (>= 5 scans each). Per outcome, the pieces seen
at both places that had a chair refused as them this run, by the matching test that refused it
(``GatmoMapper.refusals``: score, free_space, too_little, larger, beams, ...).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np

from benchmarks._overrides import add_override_args
from benchmarks.bench_gatmo_sim import by_run_and_start, refusals_of

OUT = Path("bench-out")


def pose_errors(n: int, std_xy_m: float, std_yaw_deg: float, rng: np.random.Generator,
                rho: float = 0.95) -> np.ndarray:
    """(n, 3) pose errors: per axis an AR(1) series with correlation ``rho`` per step and
    stationary standard deviations (std_xy_m, std_xy_m, std_yaw_deg in radians)."""
    std = np.array([std_xy_m, std_xy_m, np.radians(std_yaw_deg)])
    out = np.empty((n, 3))
    e = rng.normal(0.0, std)
    for i in range(n):
        out[i] = e
        e = rho * e + np.sqrt(1.0 - rho**2) * rng.normal(0.0, std)
    return out


def error_band(err: np.ndarray, trusted: np.ndarray, band: str) -> np.ndarray:
    """The part ``band`` (see the module docstring) of a pose error series ``err`` (N, 3)
    [m, m, rad]; ``trusted`` (N,) bool: the scans whose error makes the constant."""
    from scipy.ndimage import uniform_filter1d

    if band == "all":
        return err
    if band == "none":
        return np.zeros_like(err)
    if band == "const":
        ref = err[trusted] if trusted.any() else err
        return np.broadcast_to(np.median(ref, axis=0), err.shape).copy()
    slow = uniform_filter1d(err, 101, axis=0, mode="nearest")
    if band == "slow":
        return slow
    mid = uniform_filter1d(err, 15, axis=0, mode="nearest")
    if band == "mid":
        return mid - slow
    if band == "fast":
        return err - mid
    raise ValueError(f"unknown error band {band!r}")


def stack_poses(scen, cfg, tmp: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per run (poses (N, 3), trusted (N,) bool): the base poses (map frame) the full stack
    handed GATMO as trusted, and its published pose on the other scans."""
    from gatmo.pipeline.runs import compare

    res = compare(scen.map_yaml, scen.logs, tmp / "stack", scenario_json=scen.scenario_json,
                  config=cfg, pictures=False, keep_traces=True, sides=("gatmo",))
    out = []
    for k in range(len(scen.logs)):
        tr = res.traces[(k, "gatmo")]
        trusted = np.isfinite(tr.gatmo_poses_xytheta[:, 0])
        out.append((np.where(trusted[:, None], tr.gatmo_poses_xytheta, tr.poses_xytheta),
                    trusted))
    return out


def one_seed(seed: int, runs: int, tmp: Path, return_prob: float = 0.0,
             overrides: list[str] | None = None,
             pose_noise: tuple[float, float] | None = None,
             pose_source: str = "truth", band: str = "all",
             sim_overrides: list[str] | None = None) -> list[dict]:
    from benchmarks._overrides import with_overrides
    from gatmo.datasets.sim import SimConfig, simulate_scenario
    from gatmo.geometry import wrap_angle
    from gatmo.maps.io import load_map
    from gatmo.objects.mapper import GatmoMapper
    from gatmo.pipeline.config import sim_stack_config
    from gatmo.pipeline.evaluate import object_state, observed, piece_outcome, tie_objects
    from gatmo.pipeline.runs import load_scans

    sim = with_overrides(SimConfig.for_preset("hall"), sim_overrides)
    sim.rearrange.return_prob = return_prob
    scen = simulate_scenario(tmp / f"s{seed}", preset="hall", runs=runs, seed=seed, config=sim)
    doc = json.loads(Path(scen.scenario_json).read_text())
    cfg = with_overrides(sim_stack_config(), overrides)
    mapper = GatmoMapper.from_config(cfg.gatmo, load_map(scen.map_yaml))
    p2o = {v: k for k, v in tie_objects(mapper.object_map, doc).items()}
    prev = {p["id"]: p for p in doc["map_objects"]}
    rows = []
    noise_rng = np.random.default_rng([seed, 7])
    stack = stack_poses(scen, cfg, tmp / f"s{seed}") if pose_source == "stack" else None
    for k, log in enumerate(scen.logs):
        scans = load_scans(log)
        start = {pid: object_state(mapper.object_map.by_id[oid], pid, doc["map_objects"],
                                   list(prev.values()))
                 for pid, oid in p2o.items()}
        mapper.begin_run(k + 1)
        events = []
        trusted = np.ones(len(scans), dtype=bool)
        stack_err_m = None
        if stack is not None:
            pose, trusted = stack[k]
            err = pose - np.array([s.gt_pose_xytheta for s in scans], dtype=float)
            err[:, 2] = wrap_angle(err[:, 2])
            if trusted.any():  # how far off the poses the stack trusted were, this run
                stack_err_m = float(np.median(np.hypot(err[trusted, 0], err[trusted, 1])))
            err = error_band(err, trusted, band)
        elif pose_noise is None:
            err = np.zeros((len(scans), 3))
        else:
            err = pose_errors(len(scans), *pose_noise, noise_rng)
        for i, s in enumerate(scans):
            for e in mapper.update(s.gt_pose_xytheta + err[i], s, pose_confident=trusted[i],
                                   stamp_s=s.stamp_s):
                events.append(dict(e.as_dict(), scan=i))
        refusals = dict(mapper.refusals)  # this run's: the next begin_run clears them
        events += [dict(e.as_dict(), scan=len(scans)) for e in mapper.end_run()]
        run = doc["runs"][k]
        cur = {p["id"]: p for p in run["objects"]}
        for c in run["changes"]:
            pid = c["id"]
            if c["kind"] not in ("moved", "shifted") or pid not in p2o:
                continue
            o = mapper.object_map.by_id[p2o[pid]]
            rel = [e for e in events if e["object_id"] == o.id and e["kind"] == "relocated"]
            out = piece_outcome(o, pid, doc["map_objects"], run["objects"], events)
            obs = observed(scans, prev[pid], cur.get(pid))
            rows.append({"seed": seed, "run": k + 1, "label": c["label"], "kind": c["kind"],
                         "returned": bool(c.get("returned")), "observed": obs, "outcome": out,
                         "start": start[pid],
                         "scans_to_match": rel[-1]["support_scans"] if rel else None,
                         "stack_median_error_m": stack_err_m,
                         "refusals": refusals_of(refusals, o.id)})
        prev = cur
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--return-prob", type=float, default=0.0,
                    help="per piece and run, the chance it is put back where it stood before")
    ap.add_argument("--procs", type=int, default=1, help="seeds run in parallel")
    ap.add_argument("--pose-noise", default=None, metavar="XY_M,YAW_DEG",
                    help="add a slowly varying error of these standard deviations to the poses")
    ap.add_argument("--pose-source", choices=("truth", "stack"), default="truth",
                    help="stack: the scans the full stack trusted, with its error (--error-band)")
    ap.add_argument("--error-band", choices=("all", "none", "const", "slow", "mid", "fast"),
                    default="all", help="with --pose-source stack: which part of its error")
    add_override_args(ap)
    args = ap.parse_args(argv or [])
    rows: list[dict] = []
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    noise = None if args.pose_noise is None else tuple(
        float(x) for x in args.pose_noise.split(","))
    with tempfile.TemporaryDirectory() as tmp:
        job = partial(one_seed, runs=args.runs, tmp=Path(tmp), return_prob=args.return_prob,
                      overrides=args.set, pose_noise=noise, pose_source=args.pose_source,
                      band=args.error_band, sim_overrides=args.sim_set)
        with ProcessPoolExecutor(args.procs) as ex:
            for seed, r in zip(seeds, ex.map(job, seeds), strict=True):
                rows += r
                print(seed, json.dumps([(x["label"], x["observed"], x["outcome"]) for x in r]),
                      flush=True)
    table: dict = {}
    for r in rows:
        d = table.setdefault(r["observed"], {"found": 0, "twin": 0, "wrong": 0, "absent": 0,
                                             "missed": 0})
        d[r["outcome"]] += 1
    both = table.get("both", {})
    n_both = max(sum(both.values()), 1)
    scans = [r["scans_to_match"] for r in rows if r["outcome"] == "found"
             and r["scans_to_match"] is not None]
    total = {"seeds": args.seeds, "pose_noise": noise, "pose_source": args.pose_source,
             "error_band": args.error_band if args.pose_source == "stack" else None,
             "by_observability": table,
             "found_of_seen_both": both.get("found", 0) / n_both,
             "found_or_twin_of_seen_both": (both.get("found", 0) + both.get("twin", 0)) / n_both,
             "wrong_per_run": sum(d["wrong"] for d in table.values()) / (args.seeds * args.runs),
             "median_scans_to_match": float(np.median(scans)) if scans else None}
    if args.pose_source == "stack":
        # found among the pieces seen at both places, by how far off the stack's trusted poses
        # were in that run (median): is the loss spread out or in the runs it got wrong?
        for lo, hi in ((0.0, 0.03), (0.03, 0.1), (0.1, np.inf)):
            sel = [r for r in rows if r["observed"] == "both" and r["stack_median_error_m"]
                   is not None and lo <= r["stack_median_error_m"] < hi]
            total[f"found_of_seen_both_stack_error_{lo}_{hi}_m"] = (
                len(sel), sum(r["outcome"] == "found" for r in sel) / max(len(sel), 1))
    # of the pieces seen at both places, by outcome: how many had a chair refused as them, by
    # the test that refused it (GatmoMapper.refusals; a piece counts once per test)
    refused: dict = {}
    for r in rows:
        if r["observed"] == "both":
            d = refused.setdefault(r["outcome"], {"pieces": 0, "any": 0})
            d["pieces"] += 1
            d["any"] += bool(r["refusals"])
            for why in r["refusals"]:
                d[why] = d.get(why, 0) + 1
    total["refused_of_seen_both_by_outcome"] = refused
    total["seen_both_by_run_and_start"] = by_run_and_start(rows)
    back = [r for r in rows if r["returned"] and r["observed"] == "both"]
    if back:  # pieces put back where they stood before (--return-prob)
        total["returned_seen_both"] = len(back)
        total["found_of_returned_seen_both"] = sum(r["outcome"] == "found" for r in back) / len(
            back)
    print(json.dumps(total, indent=1))
    OUT.mkdir(exist_ok=True)
    (OUT / f"gatmo_oracle{args.tag}.json").write_text(
        json.dumps({"rows": rows, "total": total}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
