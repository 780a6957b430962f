"""The static localizer's failures over several filter draws (issue 6: "the static
localizer's failures (lost) must not happen with object updates").

One run of ``bench_gatmo_sim`` draws each side's particle filter once per seed (``seed`` in
the stack config; both sides share it). Whether one hall seed counts as a failure of the full
stack can hang on that one draw (hall seeds 413 and 416, twenty-sixth session), so this tool
takes several runs over the same hall seeds with other filter seeds and counts per
(hall seed, draw) pair::

    python -m benchmarks.bench_gatmo_sim --first-seed 400 --seeds 20 --no-before --procs 2 \\
        --set seed=10 --tag _400_d10
    python -m benchmarks.draws bench-out/gatmo_sim_hall_400.json \\
        bench-out/gatmo_sim_hall_400_d10.json ...

A side is *lost* in a draw when at least ``--lost-share`` of its time (over all runs of the
seed) is lost (error > 0.5 m, the comparison's own measure). Counted per pair:

- ``static_lost``: the static localizer lost;
- ``both_lost``: the static localizer lost and the full stack too (a failure that still
  happens with object updates);
- ``new_lost``: the full stack lost and the static localizer not (a failure object updates
  bring);
- ``worse``: the full stack lost more time than the static localizer by more than
  ``--margin`` (any size of loss).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from benchmarks.paired import draw_of

#: share of a seed's time lost at which a side counts as lost in that draw
LOST_SHARE = 0.05
#: time lost (share) by which the full stack must exceed the static localizer to be "worse"
MARGIN = 0.01


def pairs(docs: list[dict]) -> list[dict]:
    """One record per (hall seed, draw) from ``bench_gatmo_sim`` outputs: the draw's filter
    seed (its ``seed=`` override, 0 when none), time lost and ATE of both sides."""
    out = []
    for doc in docs:
        draw = draw_of(doc)
        for r in doc["rows"]:
            out.append({"seed": r["seed"], "draw": draw,
                        "static_lost": r["static_lost"], "gatmo_lost": r["gatmo_lost"],
                        "static_ate_m": r["static_ate_m"], "gatmo_ate_m": r["gatmo_ate_m"]})
    return out


def worse(r: dict, margin: float = MARGIN) -> bool:
    """The full stack lost more of the time than the static localizer, by over ``margin``."""
    return r["gatmo_lost"] > r["static_lost"] + margin


def count(records: list[dict], lost_share: float = LOST_SHARE,
          margin: float = MARGIN) -> dict:
    """The counts of the module docstring over all pairs, and per hall seed the draws in
    which the full stack was ``worse`` (only seeds with at least one)."""
    n = {"pairs": len(records), "static_lost": 0, "gatmo_lost": 0, "both_lost": 0,
         "new_lost": 0, "worse": 0}
    worse_by_seed: dict[int, list[int]] = {}
    for r in records:
        s_lost = r["static_lost"] >= lost_share
        g_lost = r["gatmo_lost"] >= lost_share
        n["static_lost"] += s_lost
        n["gatmo_lost"] += g_lost
        n["both_lost"] += s_lost and g_lost
        n["new_lost"] += g_lost and not s_lost
        if worse(r, margin):
            n["worse"] += 1
            worse_by_seed.setdefault(r["seed"], []).append(r["draw"])
    n["draws"] = sorted({r["draw"] for r in records})
    n["seeds"] = len({r["seed"] for r in records})
    n["worse_by_seed"] = {k: sorted(v) for k, v in sorted(worse_by_seed.items())}
    return n


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("runs", type=Path, nargs="+", help="bench_gatmo_sim outputs")
    ap.add_argument("--lost-share", type=float, default=LOST_SHARE)
    ap.add_argument("--margin", type=float, default=MARGIN)
    args = ap.parse_args(argv or [])
    records = pairs([json.loads(p.read_text()) for p in args.runs])
    for r in sorted(records, key=lambda r: (r["seed"], r["draw"])):
        flag = " worse" if worse(r, args.margin) else ""
        print(f"seed {r['seed']} draw {r['draw']:>3}: lost static {r['static_lost']:.3f} "
              f"full {r['gatmo_lost']:.3f}  ATE static {r['static_ate_m']:.3f} m "
              f"full {r['gatmo_ate_m']:.3f} m{flag}")
    print(json.dumps(count(records, args.lost_share, args.margin), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
