"""How the full stack's time per scan grows with the objects a long life leaves absent (issue
7, long life). Every absent object is a candidate each chair the robot tracks is matched
against (the paper's A list), and none is ever dropped: the 50-run soak ends with 20-30 of
them, a robot running for years would gather hundreds. One simulated hall run, the simulated
halls' configuration; before it, N absent objects are added to the object map (copies of the
hall's own pieces' shapes at random places, none of them where anything stands, so the run's
changes and matches are the same kind as in a fresh map). The peer is the same run with none
added (N = 0), timed in the same process.

    python -m benchmarks.bench_gatmo_scaling [--absent 0,100,300,1000] [--seed 400]
        [--seconds 60] [--run 1] [--set KEY=VALUE ...] [--tag NAME]

``--run K``: the timed run is run K of the object map's life, the added objects absent since
run 0 (with ``--set gatmo.absent_candidate_runs=N`` and K > N, absent too long to be tried).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

OUT = Path("bench-out")


def with_absent(mapper, n: int, rng: np.random.Generator) -> None:
    """Add ``n`` absent objects to ``mapper``'s object map: the shapes of its pieces (not
    walls), cycled, each at a uniformly random pose inside the map."""
    from gatmo.objects.objectmap import MapObject

    om = mapper.object_map
    protos = [o for o in om.objects if not o.structure and o.status in ("U", "M")]
    g = mapper.base
    lo = np.array(g.origin_xytheta[:2])
    hi = lo + np.array([g.width, g.height]) * g.resolution_m
    for k in range(n):
        p = protos[k % len(protos)]
        pose = np.array([*rng.uniform(lo, hi), rng.uniform(-np.pi, np.pi)])
        o = MapObject(om.next_id, p.label, "A", pose, p.shape_xy.copy(), p.edge_xy.copy(),
                      resolution_m=p.resolution_m)
        o.record(0, 0.0)
        om.objects.append(o)
        om.next_id += 1


def one(n_absent: int, scans, base, cfg, seed: int, run: int = 1) -> dict:
    """The full stack on ``scans`` from a fresh object map of ``base`` with ``n_absent``
    absent objects added: its ms per scan (mean, 95th percentile, max) and GATMO's events."""
    from gatmo.objects.mapper import GatmoMapper
    from gatmo.pipeline.runs import make_full_stack

    mapper = GatmoMapper.from_config(cfg.gatmo, base)
    with_absent(mapper, n_absent, np.random.default_rng(seed))
    stack = make_full_stack(cfg, mapper, 0, scans[0].gt_pose_xytheta)
    stack.begin_run(run)
    ms, kinds = [], {}
    for s in scans:
        t0 = time.perf_counter()
        st = stack.step(s)
        ms.append((time.perf_counter() - t0) * 1e3)
        for e in st.events:
            kinds[e.kind] = kinds.get(e.kind, 0) + 1
    return {"absent_added": n_absent, "ms_per_scan": float(np.mean(ms)),
            "ms_p95": float(np.percentile(ms, 95)), "ms_max": float(np.max(ms)),
            "events": kinds,
            "final_error_m": float(np.hypot(*(st.pose_xytheta[:2] - s.gt_pose_xytheta[:2])))}


def main(argv=None) -> int:
    from benchmarks._overrides import add_override_args, with_overrides
    from gatmo.datasets.carmen import CarmenLog
    from gatmo.datasets.sim import SimConfig, simulate_scenario
    from gatmo.maps.io import load_map
    from gatmo.pipeline.config import sim_stack_config

    ap = argparse.ArgumentParser()
    ap.add_argument("--absent", default="0,100,300,1000",
                    help="absent objects added, comma-separated (0 is the peer)")
    ap.add_argument("--seed", type=int, default=400)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--run", type=int, default=1, help="the timed run's number")
    add_override_args(ap)
    args = ap.parse_args(argv)
    counts = [int(x) for x in args.absent.split(",")]
    sim = SimConfig.for_preset("hall")
    sim.robot.duration_s = args.seconds
    scen = simulate_scenario(Path(tempfile.mkdtemp()) / "s", runs=1, seed=args.seed, config=sim)
    scans = list(CarmenLog(scen.logs[0]))
    base = load_map(scen.map_yaml)
    cfg = with_overrides(sim_stack_config(), args.set)
    one(0, scans[:20], base, cfg, args.seed)  # numba loads its kernels from the cache
    rows = [one(n, scans, base, cfg, args.seed, args.run) for n in counts]
    peer = next((r["ms_per_scan"] for r in rows if r["absent_added"] == 0), None)
    print(f"hall seed {args.seed}, {len(scans)} scans of {1e3 * args.seconds / len(scans):.0f}"
          " ms")
    print("absent added | ms per scan (x peer) | 95th percentile | max | events")
    for r in rows:
        ratio = f" ({r['ms_per_scan'] / peer:.1f}x)" if peer else ""
        r["x_peer"] = r["ms_per_scan"] / peer if peer else None
        print(f"{r['absent_added']} | {r['ms_per_scan']:.1f}{ratio} | {r['ms_p95']:.1f} | "
              f"{r['ms_max']:.0f} | {r['events']}")
    OUT.mkdir(exist_ok=True)
    path = OUT / f"gatmo_scaling{args.tag}.json"
    path.write_text(json.dumps({"seed": args.seed, "scans": len(scans), "run": args.run,
                                "overrides": args.set, "rows": rows}, indent=1))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
