"""``gatmo batch``: many (map, log, parameter point, seed) jobs on a process pool or Ray.

Each job writes its own folder (``DONE.json`` last: the checkpoint a re-run skips on);
``results.parquet``/``results.csv`` gathers one row per job and ``batch.json`` the counts and
every failed job (folder, log, error). A batch runs on the gatmo sources it started with: a
worker holding other code fails its jobs with ``CodeMismatch``/``CodeChanged`` instead of
mixing versions (see :func:`gatmo.batch.jobs.code_error`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from gatmo.batch.spec import BatchSpec, Job, expand_jobs, load_spec


@dataclass
class BatchResult:
    out_dir: Path
    jobs: int
    ok: int
    failed: int
    skipped: int
    results_path: Path
    scans_per_s: float
    seconds: float
    failed_jobs: list = field(default_factory=list)
    # gatmo's source files changed while the batch ran: its jobs may mix code versions
    code_changed: bool = False

    def as_dict(self) -> dict:
        return {"out_dir": str(self.out_dir), "jobs": self.jobs, "ok": self.ok,
                "failed": self.failed, "skipped": self.skipped,
                "results_path": str(self.results_path), "scans_per_s": self.scans_per_s,
                "seconds": self.seconds, "code_changed": self.code_changed,
                "failed_jobs": self.failed_jobs}


def run_batch(spec_path: str | Path, out_dir: str | Path, *, backend: str = "local",
              address: str | None = None, workers: int | None = None,
              progress: Callable[[int, int], None] | None = None) -> BatchResult:
    """Expand SPEC.yaml and run every job not finished yet on ``backend`` (local | ray).

    ``scans_per_s``: scans of the jobs run now (not skipped) / wall-clock seconds of the batch."""
    from gatmo.batch.backends import run_local, run_ray
    from gatmo.batch.jobs import finished_result, map_bundle, source_fingerprint
    from gatmo.batch.results import make_rows, write_batch_json, write_table
    from gatmo.batch.spec import apply_overrides, base_stack_config
    from gatmo.errors import ConfigError

    if backend not in ("local", "ray"):
        raise ConfigError(f"unknown backend {backend!r}: local | ray", field="--backend")
    if workers is not None and workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}", field="--workers")
    spec, _ = load_spec(spec_path)
    chains = expand_jobs(spec_path)
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    jobs = [j for ch in chains for j in ch]

    # finished jobs are skipped; a chain restarts after its last finished job
    results: dict[str, dict] = {}
    todo: list[list[Job]] = []
    for ch in chains:
        k = 0
        while k < len(ch):
            r = finished_result(ch[k], out)
            if r is None:
                break
            results[ch[k].id] = r
            k += 1
        if k < len(ch):
            # the first unfinished job needs its predecessor's objects: start the chain at the
            # finished predecessor, whose run_job returns its checkpointed result at once
            todo.append(ch[max(k - 1, 0):])

    stack_cfgs: dict = {}
    if spec.command != "echo":
        for j in jobs:
            if j.point_hash not in stack_cfgs:
                cfg = base_stack_config(j.params_path, j.preset)
                apply_overrides(cfg, j.point)
                stack_cfgs[j.point_hash] = cfg.model_dump(mode="json")
    code = source_fingerprint()
    t0 = time.perf_counter()
    if backend == "local":
        got = run_local(todo, str(out), stack_cfgs, workers=workers, progress=progress,
                        code=code)
    else:
        bundles = {j.map_name: map_bundle(j.map_yaml) for ch in todo for j in ch}
        got = run_ray(todo, str(out), stack_cfgs, bundles, address=address, workers=workers,
                      progress=progress, code=code)
    seconds = time.perf_counter() - t0
    code_after = source_fingerprint()
    for r in got:
        if r["id"] in results:
            continue  # finished before this run (the head of a resumed chain)
        if r["status"] == "skipped":
            # finished during this run by an attempt whose worker then died: the retry found
            # its checkpoint, but the job did run now
            r = dict(r, status="ok")
        results[r["id"]] = r
    param_keys = list(spec.grid)
    rows = make_rows(jobs, results, param_keys)
    path = write_table(rows, out)
    counts = {s: sum(1 for r in rows if r["status"] == s) for s in ("ok", "failed", "skipped")}
    scans = sum(float(results[j.id]["summary"].get("scans") or 0) for j in jobs
                if results[j.id]["status"] == "ok")
    failed = [{"job_id": r["job_id"], "folder": r["folder"], "log": r["log"],
               "error": r["error"]} for r in rows if r["status"] == "failed"]
    res = BatchResult(out, len(jobs), counts["ok"], counts["failed"], counts["skipped"], path,
                      scans / seconds if seconds > 0 else 0.0, seconds, failed,
                      code_changed=code_after != code)
    write_batch_json(dict(res.as_dict(), backend=backend, spec=str(Path(spec_path).resolve()),
                          code_fingerprint=[code, code_after]), out)
    return res


__all__ = ["BatchResult", "BatchSpec", "Job", "expand_jobs", "run_batch"]
