"""Run by run, two settings of the full stack from the same object map: does a change help
within a run, before the runs' chain amplifies it into a different history?

    python -m benchmarks.bench_run_paired --first-seed 300 --seeds 10 --procs 2
        [--set-b gatmo.provisional_landmarks=true ...] [--set common=value] [--tag X]

Per seed, the full stack with the A settings (``--set``) runs the simulated hall's logs as
``gatmo compare`` does, the object map carried from run to run. Then every run k is run
again, alone, from the object map A left after run k-1 (the static map for the first run):
once with the A settings and once with the B settings (``--set`` plus ``--set-b``), same
seed. Both sides of a pair start from the same map, so their difference is what the change
does within one run: ATE RMSE and time lost (error over 0.5 m), moved pieces found at the end
of the run, false relocations and twin swaps in it. Output as ``benchmarks.paired`` gives it: mean
B - A over the (seed, run) pairs with a 95 % bootstrap interval over the seeds, and on how
many pairs B is higher or lower. Output: ``bench-out/run_paired<tag>.json``.

A's replay of run k from the saved map is not always A's chained run k to the digit (the
saved map drops in-memory caches); the output has both ATEs, ``chained_ate_m`` and
``ate_a_m``.
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

OUT = Path("bench-out")
FIGURES = ("ate_m", "lost", "found", "false_relocations", "twin_relocations")
# B without --set-b (``make bench``): the matching defaults before 2026-11-26 (thirteenth
# session), run by run against today's
DEFAULT_B = ("gatmo.match_ambiguity_wait=false", "gatmo.match_ambiguity_settle=false",
             "gatmo.provisional_landmarks=false", "gatmo.provisional_min_verified_scans=9",
             "gatmo.match_min_score=0.8")


def _one_run(cfg, base, objects_path, scans, log, gt, k, scenario, ties) -> dict:
    from gatmo.pipeline.evaluate import score_run
    from gatmo.pipeline.runs import _make_mapper, make_full_stack, run_side, score

    mapper = _make_mapper(cfg, base, objects_path)
    stack = make_full_stack(cfg, mapper, cfg.seed + k, scans[0].gt_pose_xytheta)
    tr = run_side(stack, scans, log=str(log), side="gatmo", run_id=k + 1)
    row = score(tr, gt)
    o = score_run(mapper.object_map, ties, scenario, k + 1, tr.events)
    return {"ate_m": row["ate_rmse_m"], "lost": row["lost_fraction"], "found": o["found"],
            "false_relocations": o["false_relocations"],
            "twin_relocations": o["twin_relocations"], "moved": o["moved"]}


def one_seed(seed: int, runs: int, tmp: Path, set_a: list[str], set_b: list[str]) -> list[dict]:
    from benchmarks._overrides import with_overrides
    from gatmo.datasets.sim import load_scenario, simulate_scenario
    from gatmo.maps.io import load_map
    from gatmo.pipeline.config import sim_stack_config
    from gatmo.pipeline.evaluate import tie_objects
    from gatmo.pipeline.runs import _make_mapper, compare, ground_truth_of, load_scans

    scen = simulate_scenario(tmp / f"s{seed}", preset="hall", runs=runs, seed=seed)
    cfg_a = with_overrides(sim_stack_config(), set_a)
    cfg_b = with_overrides(sim_stack_config(), set_a + set_b)
    res = compare(scen.map_yaml, scen.logs, tmp / f"a{seed}", scenario_json=scen.scenario_json,
                  config=cfg_a, pictures=False, sides=("gatmo",))
    chained = [r["ate_rmse_m"] for r in res.rows if r["side"] == "gatmo"]
    base = load_map(scen.map_yaml)
    scenario = load_scenario(scen.scenario_json)
    ties = tie_objects(_make_mapper(cfg_a, base, None).object_map, scenario)
    run_dirs = sorted((tmp / f"a{seed}" / "gatmo").iterdir())
    rows = []
    for k, log in enumerate(scen.logs):
        scans = load_scans(log)
        gt = ground_truth_of(scans, log, None)
        start = None if k == 0 else run_dirs[k - 1] / "objects.json"
        a = _one_run(cfg_a, base, start, scans, log, gt, k, scenario, ties)
        b = _one_run(cfg_b, base, start, scans, log, gt, k, scenario, ties)
        rows.append({"seed": seed, "run": k + 1, "chained_ate_m": chained[k], "a": a, "b": b})
    return rows


def summarize(rows: list[dict], draws: int = 2000) -> dict:
    """Per figure: mean of A and B over the pairs, B - A with a 95 % bootstrap interval (the
    seeds resampled, their runs together: ``benchmarks.paired`` on each seed's mean over its
    runs), pairs B higher / lower."""
    from benchmarks.paired import paired

    per_seed: dict[str, dict[int, dict]] = {"a": {}, "b": {}}
    for side, by_seed in per_seed.items():
        for seed in {r["seed"] for r in rows}:
            mine = [r[side] for r in rows if r["seed"] == seed]
            by_seed[seed] = {f: float(np.mean([x[f] for x in mine])) for f in FIGURES}
    res = paired(per_seed["a"], per_seed["b"], [(f, f, None) for f in FIGURES], draws=draws)
    out = {}
    for f, d in zip(FIGURES, res, strict=True):
        a = np.array([r["a"][f] for r in rows], dtype=float)
        b = np.array([r["b"][f] for r in rows], dtype=float)
        out[f] = {"a": d["a"], "b": d["b"], "b_minus_a": d["b_minus_a"], "ci95": d["ci95"],
                  "b_higher": int(np.sum(b > a + 1e-9)), "b_lower": int(np.sum(b < a - 1e-9)),
                  "pairs": len(rows)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--first-seed", type=int, default=300)
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--procs", type=int, default=1, help="seeds run in parallel")
    ap.add_argument("--set-b", action="append", default=[], metavar="KEY=VALUE",
                    help="B's overrides on top of --set (repeatable); default DEFAULT_B")
    add_override_args(ap)
    args = ap.parse_args(argv or [])
    if not args.set_b:  # make bench: the last setting measured this way (docs/experiments.md)
        args.set_b = list(DEFAULT_B)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        job = partial(one_seed, runs=args.runs, tmp=Path(tmp), set_a=args.set,
                      set_b=args.set_b)
        with ProcessPoolExecutor(args.procs) as ex:
            for r in ex.map(job, seeds):
                rows += r
                for x in r:
                    print(x["seed"], x["run"], f"chained {x['chained_ate_m']:.3f}",
                          "A", json.dumps(x["a"]), "B", json.dumps(x["b"]), flush=True)
    total = summarize(rows)
    for f, d in total.items():
        print(f"{f:20s} A {d['a']:.3f}  B {d['b']:.3f}  B-A {d['b_minus_a']:+.3f} "
              f"[{d['ci95'][0]:+.3f}, {d['ci95'][1]:+.3f}]  B higher {d['b_higher']}, "
              f"lower {d['b_lower']} of {d['pairs']}")
    OUT.mkdir(exist_ok=True)
    (OUT / f"run_paired{args.tag}.json").write_text(json.dumps(
        {"set_a": args.set, "set_b": args.set_b, "rows": rows, "total": total}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
