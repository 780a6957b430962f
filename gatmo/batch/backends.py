"""Where chains run: ``local`` (process pool, spawn) or ``ray`` (Ray tasks).

Both take chains of jobs (see :func:`gatmo.batch.spec.expand_jobs`) and return one result dict
per job. Job errors never escape a task (they are recorded as ``failed``), so Ray's
``max_retries`` only ever re-runs tasks whose worker died; ``retry_exceptions=False``.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

from gatmo.batch.jobs import _result, finished_result, run_chain, run_job
from gatmo.batch.spec import Job

Progress = Callable[[int, int], None] | None
RAY_MAX_RETRIES = 3


def run_local(chains: list[list[Job]], out_root: str, stack_cfgs: dict, *,
              workers: int | None = None, progress: Progress = None) -> list[dict]:
    """Chains in parallel on a spawn-context process pool, each chain sequential in one task.
    ``workers`` defaults to ``os.cpu_count()``; 1 worker runs in this process."""
    total = sum(len(c) for c in chains)
    results: list[dict] = []
    workers = workers or os.cpu_count() or 1
    if workers == 1 or len(chains) <= 1:
        for ch in chains:
            results.extend(run_chain(ch, out_root, None, stack_cfgs))
            if progress is not None:
                progress(len(results), total)
        return results
    ctx = mp.get_context("spawn")
    n = min(workers, len(chains))
    # processes replace numba's threads: share the cores instead of oversubscribing them
    threads = max(1, (os.cpu_count() or 1) // n)
    with ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_init_worker,
                             initargs=(threads,)) as pool:
        futs = {pool.submit(run_chain, ch, out_root, None,
                            {j.point_hash: stack_cfgs.get(j.point_hash) for j in ch}): ch
                for ch in chains}
        for f in as_completed(futs):
            try:
                results.extend(f.result())
            except BrokenProcessPool as exc:  # a worker died (OOM, kill): record, go on
                results.extend(_lost(futs[f], out_root, exc))
            if progress is not None:
                progress(len(results), total)
    return results


def _lost(chain: list[Job], out_root: str, exc: Exception) -> list[dict]:
    """Results of a chain whose worker process died: finished jobs keep their checkpoint, the
    others are failed (no DONE.json, so the next run of the batch redoes them)."""
    out = []
    for job in chain:
        r = finished_result(job, out_root)
        out.append(r if r is not None else _result(
            job, "failed", error=f"WorkerLost: {type(exc).__name__}: worker process died"))
    return out


def run_ray(chains: list[list[Job]], out_root: str, stack_cfgs: dict, map_bundles: dict, *,
            address: str | None = None, workers: int | None = None,
            progress: Progress = None) -> list[dict]:
    """One Ray task per job. A chain is a sequence of task dependencies: task K receives task
    K-1's result ObjectRef (Ray waits for it and passes the value). Maps and parameter points
    are ``ray.put`` once and shared by every job that uses them. ``address`` goes to
    ``ray.init`` (None: a local instance with ``num_cpus=workers``); an already initialised
    Ray (e.g. a test's) is used as is."""
    from gatmo.errors import require

    ray = require("ray", "ray")
    started = False
    if not ray.is_initialized():
        kw = {"include_dashboard": False, "log_to_driver": False}
        if address is None:
            kw["num_cpus"] = workers or os.cpu_count() or 1
        ray.init(address=address, **kw)
        started = True
    try:
        task = ray.remote(max_retries=RAY_MAX_RETRIES, retry_exceptions=False)(_ray_job)
        map_refs = {name: ray.put(b) for name, b in map_bundles.items()}
        cfg_refs = {h: ray.put(c) for h, c in stack_cfgs.items()}
        refs = []
        for ch in chains:
            prev = None
            for job in ch:
                prev = task.remote(job, out_root, map_refs.get(job.map_name),
                                   cfg_refs.get(job.point_hash), prev)
                refs.append(prev)
        total = len(refs)
        results: list[dict] = []
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            results.extend(ray.get(ready))
            if progress is not None:
                progress(len(results), total)
        return results
    finally:
        if started:
            ray.shutdown()


def _init_worker(threads: int) -> None:
    """Spawned pool worker: cap numba's thread pool before numba is first imported."""
    os.environ["NUMBA_NUM_THREADS"] = str(threads)


def _ray_job(job: Job, out_root: str, bundle, stack_cfg, prev):
    # a Ray task holds one CPU: numba's parallel kernels get one thread in it
    try:
        import numba

        numba.set_num_threads(1)
    except ImportError:  # pragma: no cover - numba is a core dependency
        pass
    return run_job(job, out_root, map_bundle_=bundle, stack_cfg=stack_cfg, prev=prev)


__all__ = ["run_local", "run_ray"]
