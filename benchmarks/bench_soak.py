"""Soak (issue 7): many consecutive simulated runs with the object map carried over, the
furniture rearranged every time. Per run: objects placed in the map vs pieces in the world
and what those objects stand on (``map_census``: a piece, a second object on a piece, nothing),
peak RSS, ms per scan, localization error (and the static-map localizer's on the same log,
the peer), and the relocations (moved pieces found with their
id at the true pose, false relocations, the fraction of the map's pieces placed right); the
scans GATMO took from trusted poses and, of the pieces no object stands on, those the run saw
at all (``pieces_unmapped_seen``). What must stay flat stays flat, or it shows here.

    python -m benchmarks.bench_soak [--runs 50] [--seconds 30] [--seed 11] [--set KEY=VALUE ...]
        [--tag NAME]
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._overrides import add_override_args, with_overrides

OUT = Path("bench-out")


def soak(runs: int, seconds: float, seed: int = 11, tmp: Path | None = None,
         overrides: list[str] | None = None) -> list[dict]:
    from gatmo.datasets.carmen import CarmenLog
    from gatmo.datasets.sim import SimConfig, simulate_scenario
    from gatmo.maps.io import load_map
    from gatmo.objects.mapper import GatmoMapper
    from gatmo.pipeline.config import sim_stack_config
    from gatmo.pipeline.evaluate import map_census, score_run, tie_objects, unmapped_seen
    from gatmo.pipeline.runs import make_full_stack, make_localizer

    tmp = tmp or Path(tempfile.mkdtemp())
    sim = SimConfig.for_preset("hall")
    sim.robot.duration_s = seconds
    scen = simulate_scenario(tmp / "soak", runs=runs, seed=seed, config=sim)
    doc = json.loads(scen.scenario_json.read_text())
    cfg = with_overrides(sim_stack_config(), overrides)
    base = load_map(scen.map_yaml)
    mapper = GatmoMapper.from_config(cfg.gatmo, base)
    ties = tie_objects(mapper.object_map, doc)
    rows = []
    for k, log in enumerate(scen.logs):
        scans = list(CarmenLog(log))
        # the objects standing where no piece stands in this run's layout: what GATMO should
        # notice gone in it (stale_why, below)
        stale0 = map_census(mapper.object_map, ties, doc, k + 1)["stale_ids"]
        seen0 = mapper.counts["seen_through_scans"]
        # the stack as `gatmo compare` builds it (the anchor filter too, where it is on)
        stack = make_full_stack(cfg, mapper, k, scans[0].gt_pose_xytheta)
        stack.begin_run(k + 1)
        err = []
        events = []
        step_ms = []  # the stack's own work per scan; the evaluation below is not timed
        trusted = 0  # scans GATMO took from a pose the stack trusted
        for s in scans:
            t0 = time.perf_counter()
            st = stack.step(s)
            step_ms.append((time.perf_counter() - t0) * 1e3)
            trusted += st.gatmo_pose_xytheta is not None
            err.append(np.hypot(*(st.pose_xytheta[:2] - s.gt_pose_xytheta[:2])))
            events += [e.as_dict() for e in st.events]
        why = stale_why(mapper, stale0, scans, events)
        t0 = time.perf_counter()
        events += [e.as_dict() for e in stack.end_run()]
        end_ms = (time.perf_counter() - t0) * 1e3
        score = score_run(mapper.object_map, ties, doc, k + 1, events)
        # the peer: the static-map localizer alone on the same log, same seed
        static = make_localizer(cfg, base, k, scans[0].gt_pose_xytheta, False)
        static_err = []
        for s in scans:
            est = static.update(s.odom_pose_xytheta, s)
            static_err.append(np.hypot(*(est.pose_xytheta[:2] - s.gt_pose_xytheta[:2])))
        om = mapper.object_map
        census = map_census(om, ties, doc, k + 1)
        # of the stale objects, those the next run's localizer leaves out of its map
        # (gatmo.withhold_unseen_runs: no return has confirmed them for that many runs)
        stale_withheld = len(set(census["stale_ids"]) & mapper.withheld_ids())
        rows.append({
            "run": k + 1,
            "pieces_in_world": len(doc["runs"][k]["objects"]),
            "objects_placed": sum(1 for o in om.placed() if not o.structure),
            "objects_total": len(om.objects),
            "absent": len(om.A), "gamma": len(om.Gamma),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "ms_per_scan": (sum(step_ms) + end_ms) / len(scans),
            "ms_per_scan_max": max(step_ms),
            "median_err_m": float(np.median(err)),
            "static_median_err_m": float(np.median(static_err)),
            "lost_fraction": float(np.mean(np.asarray(err) > 0.5)),
            "static_lost_fraction": float(np.mean(np.asarray(static_err) > 0.5)),
            "moved": score["moved"], "found": score["found"],
            "false_relocations": score["false_relocations"],
            "map_correct_fraction": score["map_correct_fraction"],
            **{key: v for key, v in census.items() if key != "stale_ids"},
            "stale_withheld": stale_withheld,
            # of the pieces no object stands on, those the run saw (the rest it never did)
            "pieces_unmapped_seen": unmapped_seen(om, doc, k + 1, scans),
            "gatmo_scans": trusted,
            "seen_through_scans": mapper.counts["seen_through_scans"] - seen0,
            **why,
        })
    return rows


def stale_why(mapper, stale_ids: list[int], scans, events: list[dict]) -> dict:
    """Why the objects that were stale at a run's start (their piece not in the run's layout)
    are or are not taken off the map in it, counted as ``stale_*``: ``absent`` (marked absent
    this run), ``unseen`` (from the true poses no 3 scans saw through 30 % of its cells, or
    under 30 % in all: nothing to notice), ``no_evidence`` (seen through from the true poses,
    but GATMO counted no ray or beam through it: the scans it took from confirmed poses did
    not reach it), ``partial`` (some evidence, short of the absence test). Read before
    ``end_run``, which keeps the evidence for the next run only."""
    from gatmo.pipeline.evaluate import seen_through

    absent = {e["object_id"] for e in events if e["kind"] == "absent"}
    out = {"stale_at_start": len(stale_ids), "stale_absent": 0, "stale_unseen": 0,
           "stale_no_evidence": 0, "stale_partial": 0}
    for oid in stale_ids:
        o = mapper.object_map.by_id[oid]
        if oid in absent:
            out["stale_absent"] += 1
            continue
        union, n = seen_through(o.cells_world(), scans, mapper.cfg.absence_max_range_m)
        ev = mapper.absence_evidence(oid)
        if n < 3 or union.mean() < 0.3:
            out["stale_unseen"] += 1
        elif ev["rays"] == 0 and ev["beams_through"] == 0:
            out["stale_no_evidence"] += 1
        else:
            out["stale_partial"] += 1
    return out


def summary(rows: list[dict], first: int = 10) -> dict:
    """The README's soak figures: per window of runs (1..first, the rest), the median over runs
    of each side's median error, the mean time lost, runs where the full stack's median error
    is within 5 % of the static localizer's or better, moved pieces found and false
    relocations, the mean fraction of the map's pieces placed right and the mean counts of
    duplicate and stale objects after each run; the objects placed
    against the pieces standing, first and last run; peak RSS; the stack's ms per scan (the
    runs' means, lowest and highest) and its slowest single scan."""
    out: dict = {}
    for name, sel in ((f"runs 1-{first}", rows[:first]),
                      (f"runs {first + 1}-{len(rows)}", rows[first:])):
        if not sel:
            continue
        out[name] = {
            "median_err_m": float(np.median([r["median_err_m"] for r in sel])),
            "static_median_err_m": float(np.median([r["static_median_err_m"] for r in sel])),
            "lost": float(np.mean([r["lost_fraction"] for r in sel])),
            "static_lost": float(np.mean([r["static_lost_fraction"] for r in sel])),
            "not_worse": f"{sum(r['median_err_m'] <= 1.05 * r['static_median_err_m'] for r in sel)}"
                         f" of {len(sel)}",
            "found_of_moved": f"{sum(r['found'] for r in sel)} of {sum(r['moved'] for r in sel)}",
            "false_relocations": int(sum(r["false_relocations"] for r in sel)),
            "map_correct_fraction": float(np.mean([r["map_correct_fraction"] for r in sel])),
            # the map's census swings from run to run (0-5 duplicates on one chain): its mean
            # over the window says more than the last run's count
            "duplicate_mean": float(np.mean([r["duplicate"] for r in sel])),
            "stale_mean": float(np.mean([r["stale"] for r in sel])),
            # of them, left out of the next run's localizer map (rows before the sixty-third
            # session have no such count)
            "stale_withheld_mean": float(np.mean([r.get("stale_withheld", np.nan)
                                                  for r in sel])),
            "pieces_unmapped_mean": float(np.mean([r["pieces_unmapped"] for r in sel])),
            # of them, seen in the run; and GATMO's scans (rows before the seventy-third
            # session have neither count)
            "pieces_unmapped_seen_mean": float(np.mean([r.get("pieces_unmapped_seen", np.nan)
                                                        for r in sel])),
            "gatmo_scans_mean": float(np.mean([r.get("gatmo_scans", np.nan) for r in sel])),
        }
    out["stale_why_sum"] = {k: int(sum(r.get(k, 0) for r in rows))
                            for k in ("stale_at_start", "stale_absent", "stale_unseen",
                                      "stale_no_evidence", "stale_partial")}
    out["seen_through_scans_mean"] = float(np.mean([r.get("seen_through_scans", 0)
                                                    for r in rows]))
    from gatmo.pipeline.evaluate import CENSUS_KEYS

    for k in ("objects_placed", "pieces_in_world", "objects_total", "peak_rss_mb",
              *CENSUS_KEYS[1:]):
        out[k] = [rows[0][k], rows[-1][k]]
    ms = [r["ms_per_scan"] for r in rows]
    out["ms_per_scan_min_max"] = [float(min(ms)), float(max(ms))]
    out["slowest_scan_ms"] = float(max(r.get("ms_per_scan_max", float("nan")) for r in rows))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=11, help="the scenario's seed")
    add_override_args(ap)
    args = ap.parse_args(argv or [])
    rows = soak(args.runs, args.seconds, seed=args.seed, overrides=args.set)
    for r in rows:
        print(" ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                       for k, v in r.items()), flush=True)
    print(json.dumps(summary(rows), indent=1))
    OUT.mkdir(exist_ok=True)
    (OUT / f"soak{args.tag}.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
