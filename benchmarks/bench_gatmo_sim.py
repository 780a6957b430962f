"""The comparison over many simulated seeds (issues 5 and 6): static localizer vs the full stack
on rearranged halls and offices, the full stack in the same world before anything moved, and
GATMO's object figures. Seeds 100-119 and 200-209 were never used while tuning (seed 3 and
seeds 300 on were).

    python -m benchmarks.bench_gatmo_sim [--seeds 10] [--preset hall] [--runs 4] [--procs 2]
        [--no-before] [--set fusion.align_to_map=false ...] [--tag NAME]

``--procs``: seeds run in parallel processes (same figures); ``--no-before``: skip the same
world before anything moved (half the time; the before ratio is then missing).

Writes bench-out/gatmo_sim_<preset>.json and prints one line per seed and the totals.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np

OUT = Path("bench-out")


def stack_config(overrides: list[str] | None = None):
    """The demo's stack config with ``key=value`` overrides (dotted keys, YAML values)."""
    from benchmarks._overrides import with_overrides
    from gatmo.pipeline.config import sim_stack_config

    return with_overrides(sim_stack_config(), overrides)


def one_seed(seed: int, preset: str, runs: int, tmp: Path, seconds: float | None = None,
             overrides: list[str] | None = None, before: bool = True,
             sim_overrides: list[str] | None = None,
             static_overrides: list[str] | None = None) -> dict:
    from benchmarks._overrides import static_amcl, with_overrides
    from gatmo.datasets.sim import SimConfig, simulate_scenario
    from gatmo.pipeline.runs import compare

    sim = with_overrides(SimConfig.for_preset(preset), sim_overrides)
    if seconds is not None:
        sim.robot.duration_s = seconds
    scen = simulate_scenario(tmp / f"s{seed}", preset=preset, runs=runs, seed=seed, config=sim)
    t0 = time.perf_counter()
    cfg = stack_config(overrides)
    res = compare(scen.map_yaml, scen.logs, tmp / f"c{seed}", scenario_json=scen.scenario_json,
                  config=cfg, pictures=False, keep_traces=True,
                  static_amcl=static_amcl(cfg, static_overrides))
    outcomes = piece_outcomes(scen, res, tmp / f"c{seed}")
    census = last_census(scen, tmp / f"c{seed}")
    secs = time.perf_counter() - t0
    before_ate_m = float("nan")
    # GATMO's changes to the map in that world: every one is false (nothing moved; people
    # walk), a relocation, an absence or an object added
    before_changes = dict.fromkeys(("relocated", "absent", "added"), float("nan"))
    if before:  # the same world before anything moved: same seed, no rearrangement
        still = with_overrides(SimConfig.for_preset(preset), sim_overrides)
        still.robot.duration_s = sim.robot.duration_s
        r = still.rearrange
        r.move_prob = r.shift_prob = r.remove_prob = 0.0
        r.add_count = 0
        base = simulate_scenario(tmp / f"b{seed}", preset=preset, runs=runs, seed=seed,
                                 config=still)
        res_b = compare(base.map_yaml, base.logs, tmp / f"d{seed}",
                        config=stack_config(overrides), pictures=False)
        before_ate_m = res_b.overall["gatmo"]["ate_rmse_m"]
        before_changes = {k: sum(x.get(k, 0) for x in res_b.rows if x["side"] == "gatmo")
                          for k in before_changes}
    g = [x for x in res.rows if x["side"] == "gatmo"]
    out = {
        "seed": seed,
        "static_ate_m": res.overall["static"]["ate_rmse_m"],
        "gatmo_ate_m": res.overall["gatmo"]["ate_rmse_m"],
        "before_ate_m": before_ate_m,
        **{f"before_{k}": v for k, v in before_changes.items()},
        "static_lost": res.overall["static"]["lost_fraction"],
        "gatmo_lost": res.overall["gatmo"]["lost_fraction"],
        "moved": sum(x.get("obj_moved", 0) for x in g),
        "found": sum(x.get("obj_found", 0) for x in g),
        "absent_events": sum(x.get("absent", 0) for x in g),
        "gone": sum(x.get("obj_gone", 0) for x in g),
        "gone_noticed": sum(round(x.get("obj_gone", 0) * x.get("obj_absent_recall", 0.0))
                            for x in g if x.get("obj_gone", 0)),
        "false_relocations": sum(x.get("obj_false_relocations", 0) for x in g),
        "twin_relocations": sum(x.get("obj_twin_relocations", 0) for x in g),
        "false_relocations_carried": sum(x.get("obj_false_relocations_carried", 0) for x in g),
        "twin_relocations_carried": sum(x.get("obj_twin_relocations_carried", 0) for x in g),
        "false_absences": sum(x.get("obj_false_absences", 0) for x in g),
        "map_correct_last": g[-1].get("obj_map_correct_fraction", float("nan")),
        **{f"last_{k}": v for k, v in census.items()},
        "gatmo_ms_per_scan": res.overall["gatmo"]["ms_per_scan"],
        "static_ms_per_scan": res.overall["static"]["ms_per_scan"],
        "compare_s": secs,
        "outcomes": outcomes,
    }
    return out


def piece_outcomes(scen, res, cmp_dir: Path) -> list[dict]:
    """Per moved piece and run (paper, Table II / Fig. 5): label, outcome (found: right
    object at the true pose; twin: its object at the true pose of an identical piece (the map
    is right, the identity swapped); wrong: its object relocated elsewhere; absent: noticed
    gone, not found; missed), whether the robot could have found it (``observed``: both its
    old place seen through and its new place seen, from the true poses: "both", "old", "new",
    "none"), for relocations the scan index at which it happened, the matching tests that
    refused a chair as its object that run (``refusals``: test -> count; of them, those that
    refused the chair at its new place: ``refusals_at_new_place``, :func:`refusals_near`),
    what stands on its new place at the run's end (``new_place``, :func:`new_place`), and
    the evidence GATMO had of it (:func:`piece_evidence`)."""
    from gatmo.maps.object_io import load_objects
    from gatmo.pipeline.evaluate import (
        object_state,
        objects_on_pieces,
        observed,
        piece_outcome,
        piece_views,
        tie_objects,
    )
    from gatmo.pipeline.runs import load_scans

    doc = json.loads(Path(scen.scenario_json).read_text())
    folders = sorted((cmp_dir / "gatmo").glob("*"))
    out = []
    prev = {p["id"]: p for p in doc["map_objects"]}
    om = None
    for k, run in enumerate(doc["runs"]):
        scans = load_scans(scen.logs[k])
        cur = {p["id"]: p for p in run["objects"]}
        om_start = om  # the object map this run started from (None: the static map's)
        om = load_objects(folders[k] / "objects.json")
        ties = tie_objects(om, doc)
        p2o = {v: o for o, v in ties.items()}
        trace = res.traces[(k, "gatmo")]
        events = trace.events
        gt = np.array([sc.gt_pose_xytheta for sc in scans])
        on, _ = objects_on_pieces(om, doc, k + 1)
        labels = {p["id"]: p["label"] for p in run["objects"]}
        for c in run["changes"]:
            if c["kind"] not in ("moved", "shifted") or c["id"] not in p2o:
                continue
            o = om.by_id[p2o[c["id"]]]
            rel = [e for e in events if e["kind"] == "relocated" and e["object_id"] == o.id]
            kind = piece_outcome(o, c["id"], doc["map_objects"], run["objects"], events)
            old_xy, new_xy = np.asarray(c["old_pose"][:2]), np.asarray(c["new_pose"][:2])
            views = piece_views(scans, prev[c["id"]], cur.get(c["id"]))
            out.append({"run": k + 1, "label": c["label"], "outcome": kind, "kind": c["kind"],
                        "moved_m": round(float(np.linalg.norm(new_xy - old_xy)), 3),
                        "observed": observed(scans, prev[c["id"]], cur.get(c["id"]),
                                             views=views),
                        "scan": rel[-1]["scan_index"] if rel else None,
                        # the static map a first run starts from is the layout before it
                        "start": "right" if om_start is None else object_state(
                            om_start.by_id[o.id], c["id"], doc["map_objects"],
                            list(prev.values())),
                        "refusals": refusals_of(trace.refusals, o.id),
                        "refusals_at_new_place": refusals_near(
                            trace.refused_at, o.id, cur.get(c["id"])),
                        "new_place": new_place(o.id, on.get(c["id"], []), c["label"], ties,
                                               labels, events),
                        **piece_evidence(views[0] | views[1], trace, gt),
                        **new_place_views(views[1], trace)})
        prev = cur
    return out


def new_place(object_id: int, on: list[int], label: str, ties: dict[int, int],
              labels: dict[int, str], events: list[dict]) -> str:
    """What stands on a moved piece's new place in the object map at the run's end (``on``:
    the ids of the objects on the piece, :func:`~gatmo.pipeline.evaluate.objects_on_pieces`):
    "own" (its object ``object_id``), "twin" (an object tied to another piece of the piece's
    ``label``; ``labels``: piece id -> label), "added" (a new object added this run: the map
    right, the identity lost), "other" (any other object), or "nothing"."""
    if object_id in on:
        return "own"
    if any(labels.get(ties.get(oid, -1)) == label for oid in on):
        return "twin"
    added = {e["object_id"] for e in events if e["kind"] == "added"}
    if any(oid in added for oid in on):
        return "added"
    return "other" if on else "nothing"


def new_place_by_outcome(outcomes: list[dict]) -> dict:
    """Over pieces seen at both places: per outcome, what stands on the new place at the run's
    end (:func:`new_place`: own, twin, added, other, nothing), and the share of those pieces
    whose new place holds some object put there (``mapped``: the localizer's map right
    there, whatever the identity). A missed piece shifted by less than its size may have its
    own object, never moved, still covering half its new footprint: not counted as mapped."""
    both = [o for o in outcomes if o["observed"] == "both" and "new_place" in o]
    out: dict = {kind: dict(Counter(o["new_place"] for o in both if o["outcome"] == kind))
                 for kind in ("found", "twin", "wrong", "absent", "missed")}
    put = [o["new_place"] != "nothing" and not (o["outcome"] == "missed"
                                                and o["new_place"] == "own") for o in both]
    out["mapped"] = sum(put) / len(both) if both else None
    return out


def piece_evidence(seen: np.ndarray, trace, gt_xytheta: np.ndarray) -> dict:
    """What GATMO had of a piece in a run: of the scans that saw it (``seen`` (N,) bool: its
    old place seen through or its new place seen, from the true poses), how many it was handed
    from a trusted pose (``views_taken``), how many of those the scan-to-map alignment
    confirmed (``views_confirmed``: only they count for absence and the nudge), how many
    alignments did not converge (``views_not_converged``), and the median error [m] of the
    confirmed poses against ``gt_xytheta`` (N, 3) (None without any)."""
    given = trace.gatmo_poses_xytheta
    taken = _handed(seen, trace)
    confirmed = taken & trace.gatmo_verified
    err = np.hypot(*(given[confirmed, :2] - gt_xytheta[confirmed, :2]).T)
    return {"views": int(seen.sum()), "views_taken": int(taken.sum()),
            "views_confirmed": int(confirmed.sum()),
            "views_not_converged": int((seen & (trace.align_outcomes == "not_converged")).sum()),
            "confirmed_error_m": round(float(np.median(err)), 4) if len(err) else None}


def new_place_views(new: np.ndarray, trace) -> dict:
    """Of the scans that saw a piece's new place (``new`` (N,) bool, from the true poses), how
    many there were (``new_views``) and how many GATMO was handed from a trusted pose
    (``new_views_taken``): the evidence its tracks there could have. Only the filter's
    updates are handed over, every ``update_min_d_m`` of travel (docs/experiments.md,
    fifty-second session)."""
    return {"new_views": int(new.sum()), "new_views_taken": int(_handed(new, trace).sum())}


def _handed(seen: np.ndarray, trace) -> np.ndarray:
    """(N,) bool: of the scans ``seen``, those GATMO was handed from a trusted pose."""
    return seen & np.isfinite(trace.gatmo_poses_xytheta[:, 0])


def refusals_of(refusals: dict, object_id: int) -> dict:
    """Of a run's refusals ((object id, test) -> count, ``RunTrace.refusals``), those of one
    object: test -> count."""
    return {test: n for (oid, test), n in sorted(refusals.items()) if oid == object_id}


def refusals_near(refused_at: dict, object_id: int, piece: dict | None,
                  margin_m: float = 0.3) -> list[str]:
    """The tests that refused a chair as object ``object_id`` whose centre lay within the
    scenario ``piece``'s outline (its half-diagonal plus ``margin_m``) at its new pose:
    the chair at its new place, not another one tested as it (``RunTrace.refused_at``)."""
    if piece is None:
        return []
    dims = piece["shape"]["dims_m"]
    half = dims[0] if piece["shape"]["kind"] == "circle" else 0.5 * float(np.hypot(*dims[:2]))
    xy = np.asarray(piece["pose"][:2], dtype=float)
    return sorted(test for (oid, test), centres in refused_at.items() if oid == object_id
                  and any(np.hypot(cx - xy[0], cy - xy[1]) <= half + margin_m
                          for cx, cy in centres))


def refusals_by_outcome(outcomes: list[dict]) -> dict:
    """Over pieces seen at both places and not found (noticed gone, or missed): per outcome,
    how many, how many no chair was ever refused as (``never_refused``: no track was tested
    against the object that run), and per matching test how many were refused by it at least
    once (a piece refused by several tests counts under each); the same for the chair at the
    piece's new place only (``refused_at_new_place``, ``refused_at_new_place_by``: tests
    named ``gamma_*`` refused it as a Gamma object, at an absence or at the run's end)."""
    out = {}
    for kind in ("absent", "missed"):
        pieces = [o for o in outcomes if o["observed"] == "both" and o["outcome"] == kind
                  and "refusals" in o]
        tests = Counter(t for o in pieces for t in o["refusals"])
        here = Counter(t for o in pieces for t in o.get("refusals_at_new_place", []))
        out[kind] = {"pieces": len(pieces),
                     "never_refused": sum(not o["refusals"] for o in pieces),
                     "refused_by": dict(tests.most_common()),
                     "refused_at_new_place": sum(bool(o.get("refusals_at_new_place"))
                                                 for o in pieces),
                     "refused_at_new_place_by": dict(here.most_common())}
    return out


def evidence_by_outcome(outcomes: list[dict]) -> dict:
    """Over pieces seen at both places, per outcome: how many, the median share of the scans
    that saw them which GATMO took from a confirmed pose, the median of their confirmed
    poses' median error [m], and the median share of the scans that saw the new place which
    GATMO was handed (:func:`new_place_views`)."""
    out = {}
    for kind in ("found", "twin", "wrong", "absent", "missed"):
        pieces = [o for o in outcomes if o["observed"] == "both" and o["outcome"] == kind
                  and "views" in o]
        share = [o["views_confirmed"] / o["views"] for o in pieces if o["views"]]
        err = [o["confirmed_error_m"] for o in pieces if o["confirmed_error_m"] is not None]
        # (outcomes written before the fifty-second session have no new_views)
        new = [o["new_views_taken"] / o["new_views"] for o in pieces if o.get("new_views")]
        out[kind] = {"pieces": len(pieces),
                     "confirmed_share_median": float(np.median(share)) if share else None,
                     "confirmed_error_median_m": float(np.median(err)) if err else None,
                     "new_place_taken_share_median": float(np.median(new)) if new else None}
    return out


def by_run_and_start(outcomes: list[dict]) -> dict:
    """Over pieces seen at both places: per run, [pieces, found] (``found_by_run``); and per
    state of the piece's object at the run's start (``start``, :func:`~gatmo.pipeline.
    evaluate.object_state` against the layout before the run), the outcomes
    (``outcome_by_start``). Whether finds fall off after the first run, and whether because
    the map a run starts from was already wrong for the piece."""
    found: dict[int, list[int]] = {}
    start: dict[str, Counter] = {}
    for o in outcomes:
        if o["observed"] != "both":
            continue
        d = found.setdefault(int(o["run"]), [0, 0])
        d[0] += 1
        d[1] += o["outcome"] == "found"
        if "start" in o:
            start.setdefault(o["start"], Counter())[o["outcome"]] += 1
    return {"found_by_run": dict(sorted(found.items())),
            "outcome_by_start": {k: dict(v) for k, v in start.items()}}


def last_census(scen, cmp_dir: Path) -> dict:
    """:func:`~gatmo.pipeline.evaluate.map_census` of the full stack's object map after the
    last run."""
    from gatmo.maps.object_io import load_objects
    from gatmo.pipeline.evaluate import map_census, tie_objects

    doc = json.loads(Path(scen.scenario_json).read_text())
    om = load_objects(sorted((cmp_dir / "gatmo").glob("*"))[-1] / "objects.json")
    return map_census(om, tie_objects(om, doc), doc, len(doc["runs"]))


def table_ii(rows: list[dict]) -> dict:
    """Outcome counts per label over all seeds and runs (the paper's Table II, by outcome)."""
    t: dict[str, dict[str, int]] = {}
    for r in rows:
        for o in r["outcomes"]:
            d = t.setdefault(o["label"], {"found": 0, "twin": 0, "wrong": 0, "absent": 0,
                                          "missed": 0})
            d[o["outcome"]] += 1
    return t


def fig_5(rows: list[dict], path: Path) -> None:
    """Correct identifications vs scans into the run (the paper's Fig. 5), over all seeds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    outs = [o for r in rows for o in r["outcomes"]]
    # a piece put back where its object already stands is found without a relocation
    scans = sorted(o["scan"] for o in outs if o["outcome"] == "found" and o["scan"] is not None)
    wrong = sorted(o["scan"] for o in outs if o["outcome"] == "wrong" and o["scan"] is not None)
    n = max(len(outs), 1)
    fig, ax = plt.subplots(figsize=(5, 3.2), constrained_layout=True)
    xs = np.arange(0, 601)
    ax.step(xs, np.searchsorted(scans, xs, side="right") / n, where="post", label="correct")
    ax.step(xs, np.searchsorted(wrong, xs, side="right") / n, where="post", label="wrong object")
    ax.set_xlabel("scans into the run")
    ax.set_ylabel("fraction of moved pieces")
    ax.legend()
    path.parent.mkdir(exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    from benchmarks._overrides import add_override_args

    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--preset", default="hall")
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--seconds", type=float, default=None, help="run length (preset default)")
    ap.add_argument("--procs", type=int, default=1, help="seeds run in parallel")
    ap.add_argument("--no-before", action="store_true",
                    help="skip the world before anything moved")
    add_override_args(ap, static=True)
    args = ap.parse_args(argv or [])
    rows = []
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    with tempfile.TemporaryDirectory() as tmp:
        job = partial(one_seed, preset=args.preset, runs=args.runs, tmp=Path(tmp),
                      seconds=args.seconds, overrides=args.set, before=not args.no_before,
                      sim_overrides=args.sim_set, static_overrides=args.static_set)
        with ProcessPoolExecutor(args.procs) as ex:
            for row in ex.map(job, seeds):
                rows.append(row)
                print(" ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}"
                               for k, v in row.items() if k != "outcomes"), flush=True)
    total = summarize(rows, preset=args.preset, runs=args.runs, overrides=args.set,
                      before=not args.no_before)
    total["sim_overrides"] = args.sim_set
    total["static_overrides"] = args.static_set
    print(json.dumps(total, indent=1))
    OUT.mkdir(exist_ok=True)
    (OUT / f"gatmo_sim_{args.preset}{args.tag}.json").write_text(json.dumps({"rows": rows,
                                                                   "total": total}, indent=1))
    fig_5(rows, OUT / f"fig5_{args.preset}{args.tag}.png")
    return 0


def summarize(rows: list[dict], *, preset: str, runs: int, overrides: list[str],
              before: bool) -> dict:
    """The totals over the seeds' rows (one_seed): medians, means and sums of the numbers;
    per-seed lists (the ids of stale objects) and the outcomes are left to the rows."""
    from gatmo.pipeline.evaluate import CENSUS_KEYS

    a = {k: np.array([r[k] for r in rows], dtype=float) for k in rows[0]
         if k != "outcomes" and not isinstance(rows[0][k], list)}
    total = {
        "preset": preset, "seeds": len(rows), "overrides": overrides,
        "gatmo_over_static_ate_median": float(np.median(a["gatmo_ate_m"] / a["static_ate_m"])),
        "gatmo_over_before_ate_median": (float(np.median(a["gatmo_ate_m"] / a["before_ate_m"]))
                                         if before else None),
        "seeds_gatmo_not_worse": int(np.sum(a["gatmo_ate_m"] <= a["static_ate_m"] * 1.05)),
        "static_lost_mean": float(a["static_lost"].mean()),
        "gatmo_lost_mean": float(a["gatmo_lost"].mean()),
        "found_over_moved": float(a["found"].sum() / max(a["moved"].sum(), 1)),
        "absent_recall": float(a["gone_noticed"].sum() / max(a["gone"].sum(), 1)),
        "false_relocations_per_run": float(a["false_relocations"].sum() / (len(rows) * runs)),
        "twin_relocations_per_run": float(a["twin_relocations"].sum() / (len(rows) * runs)),
        "false_relocations_carried_per_run": float(
            a["false_relocations_carried"].sum() / (len(rows) * runs)),
        "twin_relocations_carried_per_run": float(
            a["twin_relocations_carried"].sum() / (len(rows) * runs)),
        "false_absences_per_run": float(a["false_absences"].sum() / (len(rows) * runs)),
        # the same world before anything moved: GATMO's changes per run, all false
        "before_changes_per_run": ({k: float(a[f"before_{k}"].sum() / (len(rows) * runs))
                                    for k in ("relocated", "absent", "added")}
                                   if before else None),
        # after the last run, per seed: objects on pieces, second objects on a piece, objects
        # where no piece stands, pieces no object stands on (map_census)
        "last_run_census_per_seed": {k: float(a[f"last_{k}"].mean()) for k in CENSUS_KEYS},
        "gatmo_ms_per_scan": float(a["gatmo_ms_per_scan"].mean()),
        "static_ms_per_scan": float(a["static_ms_per_scan"].mean()),
    }
    both = [o for r in rows for o in r["outcomes"] if o["observed"] == "both"]
    total["seen_both_over_moved"] = len(both) / max(a["moved"].sum(), 1)
    total["found_over_seen_both"] = sum(o["outcome"] == "found" for o in both) / max(len(both), 1)
    total["found_or_twin_over_seen_both"] = sum(o["outcome"] in ("found", "twin")
                                                for o in both) / max(len(both), 1)
    # absence recall where the robot could notice it: moved pieces whose old place it saw
    # through (>= 5 scans, true poses), taken off that place (absent, or relocated anywhere)
    seen_old = [o for r in rows for o in r["outcomes"] if o["observed"] in ("both", "old")]
    total["off_old_place_over_seen_old"] = sum(
        o["outcome"] in ("found", "twin", "wrong", "absent") for o in seen_old) / max(
        len(seen_old), 1)
    total["table_ii"] = table_ii(rows)
    total["evidence_seen_both"] = evidence_by_outcome([o for r in rows for o in r["outcomes"]])
    total["refusals_seen_both"] = refusals_by_outcome([o for r in rows for o in r["outcomes"]])
    total["seen_both_by_run_and_start"] = by_run_and_start(
        [o for r in rows for o in r["outcomes"]])
    total["new_place_seen_both"] = new_place_by_outcome([o for r in rows for o in r["outcomes"]])
    return total


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
