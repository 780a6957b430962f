"""Paired comparison of two benchmark runs over the same seeds: is B better than A, or is the
difference within the seed-to-seed swing?

    python -m benchmarks.paired bench-out/gatmo_sim_hall_A.json bench-out/gatmo_sim_hall_B.json

Takes two outputs of ``bench_gatmo_sim`` (per-seed rows) or of ``bench_gatmo_oracle`` (per-piece
rows, summed per seed over the pieces seen at both places). For each figure: A's and B's value
over the seeds both ran, B - A, a 95 % bootstrap interval of B - A (the seeds resampled with
replacement, 2000 draws, fixed seed), and on how many seeds B is higher, lower or equal. A
difference whose interval holds 0 is not one the seeds can tell from noise.

Several filter draws of the same seeds (``bench_gatmo_sim --set seed=N``, see
``benchmarks.draws``) pool into one comparison: ``--more A2.json B2.json`` (repeatable) adds a
pair of runs with another filter seed. Each (seed, draw) is then one row, and the bootstrap
resamples hall seeds with all their draws together (the draws of one seed are not
independent).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

#: (name, numerator key, denominator key or None for a mean over seeds)
SIM_FIGURES = (
    ("found of moved", "found", "moved"),
    ("false relocations per seed", "false_relocations", None),
    ("twin swaps per seed", "twin_relocations", None),
    ("noticed gone", "gone_noticed", "gone"),
    ("time lost, full stack", "gatmo_lost", None),
    ("ATE full stack m", "gatmo_ate_m", None),
)
ORACLE_FIGURES = (
    ("found of seen both", "found", "both"),
    ("found or twin of seen both", "found_or_twin", "both"),
    ("wrong of seen both", "wrong", "both"),
    ("missed of seen both", "missed", "both"),
)


def per_seed(doc: dict) -> tuple[dict[int, dict], tuple]:
    """Rows keyed by seed and the figures that apply to this kind of output."""
    rows = doc["rows"]
    if rows and "outcome" in rows[0]:  # the oracle: one row per moved piece
        out: dict[int, dict] = {}
        for r in rows:
            d = out.setdefault(r["seed"], {"found": 0, "found_or_twin": 0, "wrong": 0,
                                           "missed": 0, "both": 0})
            if r["observed"] != "both":
                continue
            d["both"] += 1
            d["found"] += r["outcome"] == "found"
            d["found_or_twin"] += r["outcome"] in ("found", "twin")
            d["wrong"] += r["outcome"] == "wrong"
            d["missed"] += r["outcome"] == "missed"
        return out, ORACLE_FIGURES
    return {r["seed"]: r for r in rows}, SIM_FIGURES


def _figure(rows: list[dict], num: str, den: str | None) -> float:
    if den is None:
        return float(np.mean([r[num] for r in rows]))
    return float(sum(r[num] for r in rows) / max(sum(r[den] for r in rows), 1))


def paired(a: dict, b: dict, figures, draws: int = 2000, seed: int = 0) -> list[dict]:
    """Per figure over the rows in both (keyed by seed, or by (seed, draw) for several filter
    draws): values, B - A, its 95 % bootstrap interval (whole seeds resampled), and the rows
    where B's value is higher / lower / equal (``seeds`` counts rows)."""
    keys = sorted(set(a) & set(b))
    if not keys:
        raise ValueError("the two runs share no seed")
    clusters: dict = {}
    for i, k in enumerate(keys):
        clusters.setdefault(k[0] if isinstance(k, tuple) else k, []).append(i)
    groups = list(clusters.values())
    rng = np.random.default_rng(seed)
    # one call, as before draws were pooled: with one row per seed the intervals are the same
    picks = [[i for g in gs for i in groups[g]]
             for gs in rng.integers(len(groups), size=(draws, len(groups)))]
    out = []
    for name, num, den in figures:
        ra = [a[k] for k in keys]
        rb = [b[k] for k in keys]
        diff = _figure(rb, num, den) - _figure(ra, num, den)
        boot = np.array([_figure([rb[i] for i in p], num, den)
                         - _figure([ra[i] for i in p], num, den) for p in picks])
        va = np.array([_figure([r], num, den) for r in ra])
        vb = np.array([_figure([r], num, den) for r in rb])
        out.append({"figure": name, "a": _figure(ra, num, den), "b": _figure(rb, num, den),
                    "b_minus_a": diff,
                    "ci95": [float(np.quantile(boot, 0.025)), float(np.quantile(boot, 0.975))],
                    "seeds_higher": int(np.sum(vb > va + 1e-12)),
                    "seeds_lower": int(np.sum(vb < va - 1e-12)),
                    "seeds": len(keys)})
    return out


def draw_of(doc: dict) -> int:
    """The filter seed a ``bench_gatmo_sim`` run used (its ``seed=`` override; 0 without)."""
    for kv in doc.get("total", {}).get("overrides") or []:
        key, _, value = kv.partition("=")
        if key.strip() == "seed":
            return int(value)
    return 0


def pooled(pairs_of_docs: list[tuple[dict, dict]]) -> tuple[dict, dict, tuple]:
    """Rows of several (A, B) pairs of runs keyed by (seed, draw), and the figures."""
    a: dict = {}
    b: dict = {}
    figures = SIM_FIGURES
    for da, db in pairs_of_docs:
        ra, figures = per_seed(da)
        rb, _ = per_seed(db)
        if len(pairs_of_docs) == 1:
            return ra, rb, figures
        if draw_of(da) != draw_of(db):
            raise ValueError(f"A and B ran with different filter seeds: {draw_of(da)}, "
                             f"{draw_of(db)}")
        a.update({(s, draw_of(da)): r for s, r in ra.items()})
        b.update({(s, draw_of(db)): r for s, r in rb.items()})
    return a, b, figures


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--more", nargs=2, type=Path, action="append", default=[],
                    metavar=("A", "B"), help="another pair of runs, with another filter seed")
    args = ap.parse_args(argv or [])
    docs = [(json.loads(x.read_text()), json.loads(y.read_text()))
            for x, y in [(args.a, args.b), *args.more]]
    a, b, figures = pooled(docs)
    rows = "(seed, draw) rows" if args.more else "seeds"
    for r in paired(a, b, figures):
        lo, hi = r["ci95"]
        tell = "" if lo <= 0.0 <= hi else "  *"
        print(f"{r['figure']:<30} A {r['a']:.3f}  B {r['b']:.3f}  B-A {r['b_minus_a']:+.3f} "
              f"[{lo:+.3f}, {hi:+.3f}]  {rows} B higher {r['seeds_higher']}, lower "
              f"{r['seeds_lower']} of {r['seeds']}{tell}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(__import__("sys").argv[1:]))
