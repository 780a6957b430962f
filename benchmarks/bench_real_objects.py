"""Were the things GATMO added to a real log's map furniture, or people who stood still? Were
the things it relocated or found absent gone from where they stood? (issue 5: no person becomes
a map object, on real data; people and doors must not turn the map absent).

No ground truth labels the Intel lab's furniture. What tells a chair from a person is time: the
robot passes the same rooms several times over the log's 45 minutes, and a person who stood
still while it was near has gone when it comes back, where a chair is still there. For every
object GATMO added at the end of the run (and, for contrast, every thing it tracked as still but
did not add: Gamma), this replays the log at the *reference* poses (Intel: the gmapping-
corrected log; ACES and MIT CSAIL: ``gatmo map build``'s optimized poses, which are also their
ATE reference; either independent of the localizer under test) and counts, scan by scan, the
beams ending on the thing's cells and the beams passing through them
(``gatmo.datasets.metrics.object_sightings``). Scans that see it are grouped into visits
(``visits``, gaps over 30 s); a visit is *there* when its scans that see the thing outnumber
those that see through it two to one, *gone* the other way round, else mixed. The map GATMO
leaves should hold what stands at the end of the log, so the last visit of 5 scans or more is
reported too: a chair that arrived late and stood there at the end is rightly added, one that
left again is not.

Relocations are checked the same way: for every object GATMO relocated, the scans after the
relocation that saw its old footprint and its new one, there or gone. A relocation of a thing
that still stands at its old place afterwards moved the map's copy away from it. And absences:
for every object found absent (and not relocated in the same step), the scans before and after
that saw its footprint there or gone; one that still stood there after was falsely absent.

    python -m benchmarks.bench_real_compare --logs aces --demo-config   # writes the run
    python -m benchmarks.bench_real_objects --log aces [--run bench-out/real_compare/aces-demo/cmp]

Needs ../shared/data (skips with a message otherwise). Writes bench-out/real_objects.json
(Intel) or bench-out/real_objects_<log>.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.bench_real_compare import DATA, LOGS, stamp_shift_s

OUT = Path("bench-out")
MIN_BEAMS = 3  # beams on (or through) a thing for a scan to count as seeing it (or not)
SIGHT_M = 8.0  # farther, a 1 deg beam spacing is wider than a chair
# the tracked outlines come from the stack's poses (0.1 m off at times), the rays from the
# reference poses: a beam ending within this of an outline hits it; one ending this far beyond
# the outline's nearest cell passes through
HIT_TOL_M = 0.25
PASS_MARGIN_M = 0.4
LAST_MIN_SCANS = 5  # a visit of fewer scans does not decide the state at the end
MAP_CELLS = (10, 100)  # the control's size range, cells (a chair is 10-60)


def sightings(objects: dict, scans) -> dict:
    """{object id: (hits (N,), passes (N,))} over the scans (reference poses)."""
    from gatmo.datasets.metrics import object_sightings
    from gatmo.geometry import compose

    centres = {k: c.mean(axis=0) for k, c in objects.items()}
    out = {k: (np.zeros(len(scans), int), np.zeros(len(scans), int)) for k in objects}
    for i, s in enumerate(scans):
        lp = compose(s.gt_pose_xytheta, s.laser_pose_xytheta)
        valid = s.valid
        for k, cells in objects.items():
            if np.hypot(*(centres[k] - lp[:2])) > SIGHT_M + 1.0:
                continue
            h, p = object_sightings(cells, lp, s.angles_rad, s.ranges_m, valid,
                                    max_range_m=SIGHT_M, hit_tol_m=HIT_TOL_M,
                                    pass_margin_m=PASS_MARGIN_M)
            out[k][0][i], out[k][1][i] = h, p
    return out


def there_gone(hits: np.ndarray, passes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per scan (N,) bool: it saw the thing there (beams ending on it, at least as many as
    passing through), and it saw it gone (beams passing through, none ending on it)."""
    return (hits >= MIN_BEAMS) & (hits >= passes), (passes >= MIN_BEAMS) & (hits == 0)


def verdicts(stamps_s: np.ndarray, hits: np.ndarray, passes: np.ndarray) -> list[dict]:
    """The visits to one thing: start and end stamps [s], and there / gone / mixed."""
    from gatmo.datasets.metrics import visits

    there, gone = there_gone(hits, passes)
    out = []
    for a, b in visits(stamps_s, there | gone):
        n_there, n_gone = int(there[a:b + 1].sum()), int(gone[a:b + 1].sum())
        kind = ("there" if n_there >= 2 * n_gone else "gone" if n_gone >= 2 * n_there
                else "mixed")
        out.append(dict(t0_s=float(stamps_s[a]), t1_s=float(stamps_s[b]), scans_there=n_there,
                        scans_gone=n_gone, kind=kind))
    return out


def after(stamps_s: np.ndarray, t_s: float, hits: np.ndarray, passes: np.ndarray) -> dict:
    """Scans after ``t_s`` [s] that saw a footprint there / gone (:func:`there_gone`)."""
    late = stamps_s > t_s
    there, gone = there_gone(hits, passes)
    return {"there": int((there & late).sum()), "gone": int((gone & late).sum())}


def relocation_rows(omap, events: list[dict], scans, stamps_s: np.ndarray,
                    shift_s: float = 0.0) -> list[dict]:
    """Per relocation event: how far it moved the object, and the scans after it that saw its
    old and its new footprint there or gone (reference poses). ``shift_s``: what the events'
    stamps add to ``stamps_s`` (:func:`benchmarks.bench_real_compare.stamp_shift_s`)."""
    moves = [e for e in events if e["kind"] == "relocated"]
    feet = {}
    for k, e in enumerate(moves):
        o = omap.by_id[e["object_id"]]
        feet[(k, "old")] = o.cells_world(np.asarray(e["pose_old"], dtype=float))
        feet[(k, "new")] = o.cells_world(np.asarray(e["pose_new"], dtype=float))
    seen = sightings(feet, scans)
    rows = []
    for k, e in enumerate(moves):
        t_s = e["stamp_s"] - shift_s
        old, new = after(stamps_s, t_s, *seen[(k, "old")]), after(stamps_s, t_s, *seen[(k, "new")])
        moved_m = float(np.hypot(*np.subtract(e["pose_new"][:2], e["pose_old"][:2])))
        rows.append(dict(
            id=e["object_id"], run=e["run"], at_s=round(float(t_s - stamps_s[0]), 1),
            moved_m=round(moved_m, 2),
            old_after=old, new_after=new,
            # still standing where it was: the relocation moved the map's copy off it (a move
            # within twice the hit tolerance leaves the two footprints indistinguishable)
            stood_at_old=bool(moved_m > 2 * HIT_TOL_M and old["there"] >= MIN_BEAMS
                              and old["there"] >= 2 * old["gone"])))
    return rows


def absence_rows(omap, events: list[dict], scans, stamps_s: np.ndarray,
                 shift_s: float = 0.0) -> list[dict]:
    """Per absence event not undone in the same step (an absence matched at once to a chair
    elsewhere is a relocation): the object's size, and the scans before and after it that saw
    its footprint there or gone (reference poses). Still there after it: a false absence."""
    moved_at = {(e["object_id"], e["stamp_s"]) for e in events if e["kind"] == "relocated"}
    gone = [e for e in events if e["kind"] == "absent"
            and (e["object_id"], e["stamp_s"]) not in moved_at]
    feet = {k: omap.by_id[e["object_id"]].cells_world(np.asarray(e["pose_old"], dtype=float))
            for k, e in enumerate(gone)}
    seen = sightings(feet, scans)
    rows = []
    for k, e in enumerate(gone):
        t_s = e["stamp_s"] - shift_s
        h, p = seen[k]
        there, away = there_gone(h, p)
        early = stamps_s <= t_s
        later = after(stamps_s, t_s, h, p)
        rows.append(dict(
            id=e["object_id"], run=e["run"], at_s=round(float(t_s - stamps_s[0]), 1),
            cells=len(feet[k]), before={"there": int((there & early).sum()),
                                        "gone": int((away & early).sum())},
            after=later,
            stood_after=bool(later["there"] >= MIN_BEAMS
                             and later["there"] >= 2 * later["gone"])))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--log", choices=LOGS, default="intel",
                    help="which log's run to check (its reference poses: Intel's corrected "
                    "log, the others' map build)")
    ap.add_argument("--run", default=None,
                    help="a `gatmo compare` output directory of that log (default: "
                    "bench-out/real_compare/<log>-demo/cmp)")
    ap.add_argument("--folder", default=None,
                    help="the run under gatmo/ (default 01_<log>; e.g. 02_intel_2of2 of a "
                    "--split 2 compare): only the reference scans within its poses' time "
                    "span count, so the last visit is that run's last")
    args = ap.parse_args(argv or [])
    run_dir = Path(args.run) if args.run else OUT / "real_compare" / f"{args.log}-demo" / "cmp"
    run = run_dir / "gatmo" / (args.folder or f"01_{args.log}")
    needs = (DATA / "radish-corrected" / "intel-corrected.log.gz" if args.log == "intel"
             else DATA / "slam-benchmark" / f"{args.log}.sort.bag")
    if not needs.exists():
        print(f"skipped: {needs} not found (the {args.log} log is needed)")
        return 0
    if not (run / "objects.json").exists():
        print(f"skipped: {run / 'objects.json'} not found; run `python -m "
              f"benchmarks.bench_real_compare --logs {args.log} --demo-config` first")
        return 0
    from benchmarks.bench_real_compare import reference_scans
    from gatmo.maps.object_io import load_objects

    shift_s = stamp_shift_s(args.log)
    omap = load_objects(run / "objects.json")
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    added = {e["object_id"] for e in events if e["kind"] == "added"}
    # (a Gamma object later taken as an absent object's new place has left the map)
    gamma = {e["object_id"] for e in events if e["kind"] == "gamma"
             and e["object_id"] in omap.by_id} - added
    first_seen = {e["object_id"]: e["stamp_s"] - shift_s for e in events
                  if e["kind"] == "gamma"}
    # the control: pieces of the static map of a chair's size, which the map says stand still
    # (some are doors or things that came and went while the map was recorded)
    control = {o.id for o in omap.objects if o.status == "U" and not o.structure
               and MAP_CELLS[0] <= len(o.shape_xy) <= MAP_CELLS[1]}
    group = {**{k: "map" for k in control}, **{k: "Gamma" for k in gamma},
             **{k: "added" for k in added}}
    things = {k: omap.by_id[k].cells_world() for k in sorted(group)}
    scans = reference_scans(args.log)
    if (run / "poses.tum").exists():  # the run's own time span (a part of a split log)
        from gatmo.datasets.tum import read_tum

        t_run, _ = read_tum(run / "poses.tum")
        scans = [s for s in scans if t_run[0] <= s.stamp_s <= t_run[-1]]
    stamps = np.array([s.stamp_s for s in scans]) - shift_s
    seen = sightings(things, scans)
    rows = []
    for k, (h, p) in seen.items():
        v = verdicts(stamps, h, p)
        there = [x for x in v if x["kind"] == "there"]
        span = there[-1]["t1_s"] - there[0]["t0_s"] if there else 0.0
        # the map at the end of the run should hold what stands at the end of the log
        last = [x["kind"] for x in v if x["scans_there"] + x["scans_gone"] >= LAST_MIN_SCANS]
        rows.append(dict(
            id=k, group=group[k], centre_xy=np.round(things[k].mean(axis=0), 2).tolist(),
            tracked_at_s=round(first_seen.get(k, float("nan")) - stamps[0], 1),
            visits=len(v), there=len(there), gone=sum(x["kind"] == "gone" for x in v),
            mixed=sum(x["kind"] == "mixed" for x in v), there_span_s=round(span, 1),
            # seen standing there on two visits a minute or more apart
            persistent=bool(len(there) >= 2 and span >= 60.0),
            last_visit=last[-1] if last else None, visit_list=v))
    summary = {}
    for g in ("added", "Gamma", "map"):
        sel = [r for r in rows if r["group"] == g and r["visits"] > 0]
        n_v = sum(r["visits"] for r in sel)
        summary[g] = dict(
            objects=len(sel), visits=n_v,
            there_of_visits=sum(r["there"] for r in sel) / max(n_v, 1),
            gone_of_visits=sum(r["gone"] for r in sel) / max(n_v, 1),
            persistent=sum(r["persistent"] for r in sel),
            never_there=sum(r["there"] == 0 for r in sel),
            there_at_last_visit=sum(r["last_visit"] == "there" for r in sel),
            gone_at_last_visit=sum(r["last_visit"] == "gone" for r in sel))
        m = summary[g]
        print(f"{g}: {m['objects']} seen on {n_v} visits; there on {m['there_of_visits']:.0%}, "
              f"gone on {m['gone_of_visits']:.0%} of them; {m['persistent']} there on visits "
              f">= 60 s apart, {m['never_there']} never seen there; at the last visit there "
              f"{m['there_at_last_visit']}, gone {m['gone_at_last_visit']}")
        if g != "map":
            for r in sel:
                print(f"  {r['id']:4d} at {r['centre_xy']}: visits {r['visits']} (there "
                      f"{r['there']}, gone {r['gone']}, mixed {r['mixed']}), there over "
                      f"{r['there_span_s']} s, last visit {r['last_visit']}")
    moves = relocation_rows(omap, events, scans, stamps, shift_s)
    print(f"relocated: {len(moves)}")
    for r in moves:
        o, n = r["old_after"], r["new_after"]
        print(f"  {r['id']:4d} at {r['at_s']} s by {r['moved_m']} m; scans after it: old place "
              f"there {o['there']}, gone {o['gone']}; new place there {n['there']}, gone "
              f"{n['gone']}{'; still stood at its old place' if r['stood_at_old'] else ''}")
    gone = absence_rows(omap, events, scans, stamps, shift_s)
    print(f"absent: {len(gone)}, of which still stood there after: "
          f"{sum(r['stood_after'] for r in gone)}")
    for r in gone:
        b, a = r["before"], r["after"]
        print(f"  {r['id']:4d} ({r['cells']} cells) at {r['at_s']} s; scans before it: there "
              f"{b['there']}, gone {b['gone']}; after it: there {a['there']}, gone "
              f"{a['gone']}{'; still stood there' if r['stood_after'] else ''}")
    OUT.mkdir(exist_ok=True)
    name = "real_objects.json" if args.log == "intel" else f"real_objects_{args.log}.json"
    (OUT / name).write_text(json.dumps(
        {"summary": summary, "rows": rows, "relocations": moves, "absences": gone}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
