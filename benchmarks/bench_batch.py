"""``gatmo batch`` throughput: scans per second across a simulated localize sweep with 1 vs 2
local workers (process pool), optionally on Ray too. Worker start-up and numba cache loading
are inside the timing (a batch pays them). Configurations are interleaved and repeated
(``--repeat``) so that load from other processes on shared cores hits them alike; the median
of each is reported, with the ratios taken within this one run. Writes bench-out/batch.json.

    python -m benchmarks.bench_batch            # 4 logs x 2 particle counts x 2 seeds
    python -m benchmarks.bench_batch --quick    # 2 logs x 2 particle counts, 150 scans
    python -m benchmarks.bench_batch --ray      # also the ray backend with 2 CPUs

With ``--ray`` one Ray instance (2 CPUs) serves every Ray run; ``ray_init_s`` is its start-up,
outside the Ray runs' timing, and its worker processes stay up from one run to the next.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
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


def _failures(res, out_dir: Path, n: int = 3) -> list[dict]:
    """The first failed jobs with their error and the traceback's last lines (FAILED.json),
    so that a failure seen once in a benchmark can be explained afterwards."""
    got = []
    for f in res.failed_jobs[:n]:
        row = {"folder": f["folder"], "error": f["error"]}
        try:
            tb = json.loads((out_dir / f["folder"] / "FAILED.json").read_text()).get("traceback")
        except (OSError, ValueError):
            tb = None
        if tb:
            row["traceback_tail"] = tb.strip().splitlines()[-4:]
        got.append(row)
    return got


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--ray", action="store_true", help="also measure the ray backend")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=2, help="runs of each configuration")
    args = ap.parse_args(argv)
    from gatmo.batch import run_batch
    from gatmo.batch.results import read_table
    from gatmo.datasets.sim import simulate_scenario

    runs, max_scans, seeds = (2, 150, [0]) if args.quick else (4, 400, [0, 1])
    out: dict = {"cpus": os.cpu_count(), "runs": runs, "max_scans": max_scans, "seeds": seeds,
                 "load_avg_start": list(os.getloadavg()), "results": []}
    configs = [("local", w) for w in args.workers] + ([("ray", 2)] if args.ray else [])
    ray = None
    if args.ray:
        # one Ray instance for every ray run, as a cluster would be: its start-up is measured
        # once here; its workers stay up between runs (a local pool is started per batch)
        import ray

        t = time.perf_counter()
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        out["ray_init_s"] = round(time.perf_counter() - t, 2)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        scen = simulate_scenario(tmp / "sim", runs=runs, seed=3)
        spec = _write_spec(Path(scen.out_dir), max_scans, seeds)
        for rep in range(args.repeat):
            for backend, w in configs:
                out_dir = tmp / f"out_{backend}_{w}_{rep}"
                t = time.perf_counter()
                res = run_batch(spec, out_dir, backend=backend, workers=w)
                wall = time.perf_counter() - t
                # job time: each job's own seconds (map, log, filter, output), without the
                # pool's or Ray's start-up; / wall = jobs running at once on average
                job_s = sum(r["seconds"] or 0.0 for r in read_table(res.results_path)
                            if r["status"] == "ok")
                row = {"backend": backend, "workers": w, "rep": rep, "jobs": res.jobs,
                       "ok": res.ok, "failed": res.failed,
                       "scans_per_s": round(res.scans_per_s, 1), "wall_s": round(wall, 2),
                       "job_s_sum": round(job_s, 2), "busy": round(job_s / wall, 2),
                       "code_changed": res.code_changed}
                if res.failed:
                    row["first_failures"] = _failures(res, out_dir)
                out["results"].append(row)
                print(json.dumps(row), flush=True)
    if ray is not None:
        ray.shutdown()
    med = {}
    for backend, w in configs:
        vals = [r["scans_per_s"] for r in out["results"]
                if (r["backend"], r["workers"]) == (backend, w)]
        med[f"{backend}_{w}"] = round(statistics.median(vals), 1)
    out["median_scans_per_s"] = med
    out["load_avg_end"] = list(os.getloadavg())
    print("median scans/s:", json.dumps(med))
    if med.get("local_1"):
        for key in med:
            if key != "local_1":
                out[f"ratio_{key}_vs_local_1"] = round(med[key] / med["local_1"], 2)
                print(f"throughput {key} / local_1: {out[f'ratio_{key}_vs_local_1']:.2f}x")
    OUT.mkdir(exist_ok=True)
    (OUT / "batch.json").write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
