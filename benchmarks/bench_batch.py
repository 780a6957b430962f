"""``gatmo batch`` throughput: scans per second across a simulated localize sweep with 1 vs 2
local workers (process pool), optionally on Ray too. Worker start-up and numba cache loading
are inside the timing (a batch pays them). Writes bench-out/batch.json.

    python -m benchmarks.bench_batch            # 4 logs x 2 particle counts x 2 seeds
    python -m benchmarks.bench_batch --quick    # 2 logs x 2 particle counts, 150 scans
    python -m benchmarks.bench_batch --ray      # also the ray backend with 2 CPUs
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

OUT = Path("bench-out")


def _write_spec(folder: Path, max_scans: int, seeds: list[int]) -> Path:
    p = folder / "spec.yaml"
    p.write_text(f"""
maps: {{hall: map.yaml}}
logs: [{{map: hall, glob: "run_*.clf"}}]
command: localize
grid: {{amcl.max_particles: [1000, 2000], amcl.min_particles: [500]}}
seeds: {seeds}
max_scans: {max_scans}
""")
    return p


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--ray", action="store_true", help="also measure the ray backend")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args(argv)
    from gatmo.batch import run_batch
    from gatmo.datasets.sim import simulate_scenario

    runs, max_scans, seeds = (2, 150, [0]) if args.quick else (4, 400, [0, 1])
    out: dict = {"cpus": os.cpu_count(), "runs": runs, "max_scans": max_scans, "seeds": seeds,
                 "results": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        scen = simulate_scenario(tmp / "sim", runs=runs, seed=3)
        spec = _write_spec(Path(scen.out_dir), max_scans, seeds)
        backends = [("local", w) for w in args.workers] + ([("ray", 2)] if args.ray else [])
        for backend, w in backends:
            t = time.perf_counter()
            res = run_batch(spec, tmp / f"out_{backend}_{w}", backend=backend, workers=w)
            wall = time.perf_counter() - t
            row = {"backend": backend, "workers": w, "jobs": res.jobs, "ok": res.ok,
                   "failed": res.failed, "scans_per_s": round(res.scans_per_s, 1),
                   "wall_s": round(wall, 2)}
            if res.failed:
                row["first_errors"] = [f["error"] for f in res.failed_jobs[:3]]
            out["results"].append(row)
            print(json.dumps(row))
    local = {r["workers"]: r["scans_per_s"] for r in out["results"] if r["backend"] == "local"}
    if 1 in local and 2 in local and local[1] > 0:
        out["ratio_2_vs_1"] = round(local[2] / local[1], 2)
        print(f"throughput 2 workers / 1 worker: {out['ratio_2_vs_1']:.2f}x")
    OUT.mkdir(exist_ok=True)
    (OUT / "batch.json").write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
