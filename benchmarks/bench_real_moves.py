"""GATMO on real logs with furniture moved in the map (issue 5 on real data;
``gatmo.pipeline.map_moves``): pieces of the log's own map are erased where they stand and drawn
turned and shifted in free space the robot saw through; ``gatmo compare`` then runs the unchanged
log on that map. Every move's truth is exact: the place the log shows the piece at.

    python -m benchmarks.bench_real_moves [--logs intel,mit-csail,aces] [--trials 3]
                                          [--moves 4] [--seed 0] [--max-scans N]
                                          [--flat-model] [--set KEY=VALUE ...] [--tag NAME]

Per log, in the same process: the full stack on the unedited map (the peer: its ATE is the one
before anything moved, and what GATMO changes there is its baseline of false events), then per
trial the static localizer and the full stack on the edited map. Maps and reference poses are
``bench_real_compare``'s (shared cache under bench-out/real_compare/<log>/). Needs ../shared/data
(skips with a message otherwise). Writes bench-out/real_moves/<log><tag>/ and
bench-out/real_moves/figures.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.bench_real_compare import DATA, LOGS, _prepare, real_log_config, reference_scans

OUT = Path("bench-out") / "real_moves"
OUTCOMES = ("found", "elsewhere", "absent", "unchanged", "untied")
FALSE = ("false_absent", "false_relocated", "added")


def _events_of(run_dir: Path, object_ids) -> dict[int, dict]:
    """Object id -> {kind: first scan index} from a run's events.jsonl."""
    out: dict[int, dict] = {int(i): {} for i in object_ids}
    p = run_dir / "events.jsonl"
    for line in p.read_text().splitlines() if p.exists() else []:
        e = json.loads(line)
        oid = e.get("object_id")
        if oid in out:
            out[oid].setdefault(e["kind"], e["scan_index"])
    return out


def _refused_near(trace, object_id: int, true_pose, within_m: float = 0.6) -> dict[str, int]:
    """Why the object was not put on its true place: per matching test, at how many places
    within ``within_m`` of the true pose it refused a chair (``GatmoMapper.refused_at`` keeps
    each refused chair's centre once, to 0.1 m)."""
    out = {}
    for (oid, test), places in trace.refused_at.items():
        if oid != object_id:
            continue
        near = [p for p in places if np.hypot(p[0] - true_pose[0], p[1] - true_pose[1])
                <= within_m]
        if near:
            out[test] = len(near)
    return out


def _run_dir(cmp_dir: Path, bag: Path) -> Path:
    return cmp_dir / "gatmo" / f"01_{bag.stem.split('.')[0]}"


def one_log(name: str, key: str, args, cfg) -> dict:
    from gatmo.maps.io import load_map, save_map
    from gatmo.maps.object_io import load_objects
    from gatmo.objects.objectmap import ObjectMap
    from gatmo.pipeline.map_moves import apply_moves, pick_moves, score_moves, tie_moves
    from gatmo.pipeline.runs import compare

    cache = OUT.parent / "real_compare" / name
    cache.mkdir(parents=True, exist_ok=True)
    map_yaml, gt, pose0 = _prepare(name, cache)
    grid = load_map(map_yaml)
    bag = DATA / "slam-benchmark" / f"{name}.sort.bag"
    relations = DATA / "slam-benchmark" / f"{name}.relations"
    scans = reference_scans(name)
    if args.max_scans:
        from gatmo.pipeline.runs import load_scans

        last = load_scans(bag, None, args.max_scans)[-1].stamp_s
        scans = [s for s in scans if s.stamp_s <= last]
    out = OUT / key
    common = dict(initial_pose=pose0, gt_paths=[gt], relations_path=relations,
                  max_scans=args.max_scans, config=cfg)

    peer = compare(map_yaml, [bag], out / "unedited", pictures=False, sides=("gatmo",),
                   **common)
    peer_row = next(r for r in peer.rows if r["side"] == "gatmo" and r.get("log") != "all")
    base_om = ObjectMap.from_grid(grid, cfg.gatmo)
    peer_final = load_objects(_run_dir(out / "unedited", bag) / "objects.json")
    peer_score = score_moves(peer_final, {}, 0)
    res = {"log": name, "scans": len(scans), "before_ate_rmse_m": peer_row["ate_rmse_m"],
           "before_lost_fraction": peer_row["lost_fraction"],
           "before": {k: peer_score[k] for k in FALSE}, "trials": []}
    print(name, "unedited map: ATE", round(res["before_ate_rmse_m"], 3), res["before"],
          flush=True)
    for trial in range(args.trials):
        rng = np.random.default_rng(args.seed + trial)
        moves = pick_moves(grid, base_om, scans[::args.every], rng, args.moves,
                           min_views=args.min_views)
        tdir = out / f"trial{trial}"
        edited = apply_moves(grid, moves)
        edited_yaml = tdir / "map.yaml"
        tdir.mkdir(parents=True, exist_ok=True)
        save_map(edited, edited_yaml)
        cmp = compare(edited_yaml, [bag], tdir / "cmp", pictures=trial == 0, keep_traces=True,
                      **common)
        trace = cmp.traces[(0, "gatmo")]
        rows = {r["side"]: r for r in cmp.rows if r.get("log") != "all"}
        ties = tie_moves(ObjectMap.from_grid(edited, cfg.gatmo), grid, moves)
        final = load_objects(_run_dir(tdir / "cmp", bag) / "objects.json")
        sc = score_moves(final, ties, len(moves))
        ev = _events_of(_run_dir(tdir / "cmp", bag), ties)
        for pm in sc["per_move"]:
            pm.update(moves[pm["move"]].as_dict())
            pm["extent_m"] = float(np.ptp(moves[pm["move"]].cells_xy, axis=0).max())
            pm["absent_scan"] = ev[pm["object_id"]].get("absent")
            pm["relocated_scan"] = ev[pm["object_id"]].get("relocated")
            pm["refused_near_truth"] = _refused_near(trace, pm["object_id"],
                                                     ties[pm["object_id"]]["true_pose"])
        t = {"trial": trial, "moves": len(moves), **{k: sc[k] for k in OUTCOMES + FALSE},
             "added_on_moved": sc["added_on_moved"], "per_move": sc["per_move"],
             "static_ate_rmse_m": rows["static"]["ate_rmse_m"],
             "gatmo_ate_rmse_m": rows["gatmo"]["ate_rmse_m"],
             "static_lost_fraction": rows["static"]["lost_fraction"],
             "gatmo_lost_fraction": rows["gatmo"]["lost_fraction"]}
        res["trials"].append(t)
        print(name, f"trial {trial}:", {k: t[k] for k in ("moves",) + OUTCOMES + FALSE},
              "ATE static / full stack", round(t["static_ate_rmse_m"], 3),
              round(t["gatmo_ate_rmse_m"], 3), flush=True)
    res["totals"] = _totals(res)
    return res


def _totals(res: dict) -> dict:
    ts = res["trials"]
    moves = sum(t["moves"] for t in ts)
    tot = {k: sum(t[k] for t in ts) for k in OUTCOMES + FALSE + ("added_on_moved",)}
    noticed = [pm for t in ts for pm in t["per_move"] if pm["absent_scan"] is not None]
    found = [pm for t in ts for pm in t["per_move"] if pm["outcome"] == "found"]
    # put elsewhere by the absence's own match (a chair or a Gamma object seen before it):
    # no track at the true place had a chance, and once placed the object is no candidate
    at_absence = [pm for t in ts for pm in t["per_move"] if pm["outcome"] == "elsewhere"
                  and pm["absent_scan"] is not None
                  and pm["relocated_scan"] == pm["absent_scan"]]
    return {"moves": moves, **tot, "elsewhere_at_absence": len(at_absence),
            "found_fraction": tot["found"] / moves if moves else None,
            "noticed_gone_fraction": len(noticed) / moves if moves else None,
            # the baseline's false events subtracted: what the moves added
            "false_absent_per_trial_over_unedited": (
                tot["false_absent"] / len(ts) - res["before"]["false_absent"]) if ts else None,
            "false_relocated_per_trial_over_unedited": (
                tot["false_relocated"] / len(ts) - res["before"]["false_relocated"])
            if ts else None,
            "median_scans_absent_to_relocated": float(np.median(
                [pm["relocated_scan"] - pm["absent_scan"] for pm in found
                 if pm["relocated_scan"] is not None and pm["absent_scan"] is not None]))
            if found else None,
            "static_ate_rmse_m_mean": float(np.mean([t["static_ate_rmse_m"] for t in ts])),
            "gatmo_ate_rmse_m_mean": float(np.mean([t["gatmo_ate_rmse_m"] for t in ts])),
            "before_ate_rmse_m": res["before_ate_rmse_m"]}


def main(argv=None) -> int:
    from benchmarks._overrides import add_override_args, with_overrides

    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", default="intel")
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--moves", type=int, default=4, help="pieces moved per trial")
    ap.add_argument("--seed", type=int, default=0, help="trial k draws its moves with seed+k")
    ap.add_argument("--min-views", type=int, default=20,
                    help="scans (of every --every-th) that must see a piece standing and its "
                    "new place seen through")
    ap.add_argument("--every", type=int, default=3,
                    help="every this many reference scans tested for views")
    ap.add_argument("--max-scans", type=int, default=None)
    ap.add_argument("--flat-model", action="store_true",
                    help="AMCL's default likelihood field (sigma_hit 0.2 m) instead of the "
                    "demo's likelihood_field_prob (bench_real_compare --demo-config): with it the "
                    "filter is seldom confident enough for GATMO to act (README, Real logs)")
    add_override_args(ap)
    args = ap.parse_args(argv or [])
    if not (DATA / "slam-benchmark").exists():
        print(f"skipped: {DATA} not found (the Kümmerle benchmark logs are needed)")
        return 0
    names = args.logs.split(",")
    unknown = sorted(set(names) - set(LOGS))
    if unknown:
        ap.error(f"--logs: unknown log(s) {', '.join(unknown)}; choose from {', '.join(LOGS)}")
    OUT.mkdir(parents=True, exist_ok=True)
    fig_path = OUT / "figures.json"
    for name in names:
        cfg = with_overrides(real_log_config(demo_model=not args.flat_model), args.set)
        key = f"{name}-{'flat' if args.flat_model else 'demo'}{args.tag}"
        res = one_log(name, key, args, cfg)
        res["command"] = "python -m benchmarks.bench_real_moves " + " ".join(argv or [])
        # read again just before writing: another log's run may have written meanwhile
        figures = json.loads(fig_path.read_text()) if fig_path.exists() else {}
        figures[key] = res
        print(key, "totals:", {k: round(v, 3) if isinstance(v, float) else v
                               for k, v in res["totals"].items()}, flush=True)
        fig_path.write_text(json.dumps(figures, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
