"""Where chains run: ``local`` (process pool, spawn) or ``ray`` (Ray tasks).

Both take chains of jobs (see :func:`gatmo.batch.spec.expand_jobs`) and return one result dict
per job. Job errors never escape a task (they are recorded as ``failed``), so Ray's
``max_retries`` only ever re-runs tasks whose worker died; ``retry_exceptions=False``.

A worker that dies mid-job (killed, out of memory, crashed) is retried on both backends, up to
``MAX_RETRIES`` times (``1 + MAX_RETRIES`` attempts in all); after that its job is recorded
``failed`` with a ``WorkerLost`` error, the rest of its chain with a ``ChainError``, and the
batch goes on. No job is left without a result, so a batch never waits on a dead worker.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import tempfile
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from gatmo.batch.jobs import FAILED, _result, finished_result, run_chain, run_job
from gatmo.batch.spec import Job

Progress = Callable[[int, int], None] | None
MAX_RETRIES = 3
RAY_MAX_RETRIES = MAX_RETRIES  # Ray's max_retries for a job's task (read at each run_ray call)
LOCAL_MAX_RETRIES = MAX_RETRIES  # re-runs of a local chain whose worker died (read per call)


# ------------------------------------------------------------------------------- local
def run_local(chains: list[list[Job]], out_root: str, stack_cfgs: dict, *,
              workers: int | None = None, progress: Progress = None,
              code: str | None = None) -> list[dict]:
    """Chains in parallel on a spawn-context process pool, each chain sequential in one task.
    ``workers`` defaults to ``os.cpu_count()``; every job runs in a pool process (also with
    one worker), so a job that kills its process never takes the batch down.

    A worker's death breaks a ``ProcessPoolExecutor`` for every chain in it: the chains that
    had started then (each marks its start in a file) are re-run one at a time in a fresh
    one-worker pool, where a death can only be that chain's own, until they finish or have died
    ``1 + LOCAL_MAX_RETRIES`` times; chains that had not started go to a new pool. Re-runs
    resume from the checkpoints (a chain's finished jobs are not redone). ``code``: the
    batch's source fingerprint, checked by every job (see :func:`gatmo.batch.jobs.code_error`)."""
    total = sum(len(c) for c in chains)
    workers = workers or os.cpu_count() or 1
    retries = LOCAL_MAX_RETRIES
    results: list[dict] = []

    def done(res: list[dict]) -> None:
        results.extend(res)
        if progress is not None:
            progress(len(results), total)

    deaths = [0] * len(chains)
    queue = list(range(len(chains)))
    idle_breaks = 0  # pool breaks with no chain started (a worker dying before any job)
    with tempfile.TemporaryDirectory(prefix="gatmo-batch-") as marks:
        rounds = iter(range(1 << 62))
        while queue:
            started, unstarted = _pool_round(chains, queue, min(workers, len(queue)), out_root,
                                             stack_cfgs, marks, next(rounds), done, code)
            if (started or unstarted) and not started:
                idle_breaks += 1
                if idle_breaks > retries:
                    for i in unstarted:
                        done(_lost(chains[i], out_root, idle_breaks, before_start=True))
                    break
            for i in started:  # suspects: alone in a one-worker pool, until done or given up
                deaths[i] += 1
                while deaths[i] <= retries:
                    s, u = _pool_round(chains, [i], 1, out_root, stack_cfgs, marks,
                                       next(rounds), done, code)
                    if not (s or u):
                        break
                    deaths[i] += 1
                if deaths[i] > retries:
                    done(_lost(chains[i], out_root, deaths[i]))
            queue = unstarted
    return results


def _pool_round(chains: list[list[Job]], idx: list[int], n: int, out_root: str,
                stack_cfgs: dict, marks: str, tag: int, done: Callable[[list[dict]], None],
                code: str | None = None) -> tuple[list[int], list[int]]:
    """Run ``chains[i] for i in idx`` on a fresh pool of ``n`` workers; results go to ``done``.
    Returns the chains the pool lost to a dead worker: (started, not started)."""
    ctx = mp.get_context("spawn")
    # processes replace numba's threads: share the cores instead of oversubscribing them
    threads = max(1, (os.cpu_count() or 1) // n)
    lost: list[int] = []
    with ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_init_worker,
                             initargs=(threads,)) as pool:
        futs = {}
        for i in idx:
            cfgs = {j.point_hash: stack_cfgs.get(j.point_hash) for j in chains[i]}
            marker = os.path.join(marks, f"{tag}-{i}")
            futs[pool.submit(_chain_task, chains[i], out_root, cfgs, marker, code)] = i
        for f in as_completed(futs):
            i = futs[f]
            try:
                res = f.result()
            except BrokenProcessPool:  # a worker died: this chain's and every pending future
                lost.append(i)
                continue
            except Exception as exc:  # noqa: BLE001 - e.g. a result that does not pickle
                res = _lost(chains[i], out_root, 0, error=_one_line(exc))
            done(res)
    started = [i for i in lost if os.path.exists(os.path.join(marks, f"{tag}-{i}"))]
    return started, [i for i in lost if i not in started]


def _chain_task(chain: list[Job], out_root: str, stack_cfgs: dict, marker: str,
                code: str | None = None) -> list[dict]:
    """Pool task: mark the chain started (the marker outlives a killed worker), run it."""
    Path(marker).write_text(str(os.getpid()))
    try:
        return run_chain(chain, out_root, None, stack_cfgs, code)
    finally:
        Path(marker).unlink(missing_ok=True)


def _init_worker(threads: int) -> None:
    """Spawned pool worker: cap numba's thread pool before numba is first imported."""
    os.environ["NUMBA_NUM_THREADS"] = str(threads)


# --------------------------------------------------------------------------- lost jobs
def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0] if text else ''}".rstrip(": ")


def _worker_lost(attempts: int, before_start: bool = False) -> str:
    if before_start:
        return f"WorkerLost: pool workers died before starting any job ({attempts} times)"
    return f"WorkerLost: the worker process died while running this job ({attempts} attempts)"


def _record_failed(job: Job, out_root: str, error: str) -> dict:
    """A failed result for a job that could not record it itself (its worker died); writes
    its FAILED.json when the folder is reachable from here."""
    try:
        folder = Path(out_root) / job.folder
        folder.mkdir(parents=True, exist_ok=True)
        from gatmo._io import atomic_write_text

        atomic_write_text(folder / FAILED, json.dumps({"job": job.id, "error": error}))
    except OSError:  # pragma: no cover - out_root not visible from the driver
        pass
    return _result(job, "failed", error=error)


def _lost(chain: list[Job], out_root: str, attempts: int, *, error: str | None = None,
          before_start: bool = False) -> list[dict]:
    """Results of a chain given up on: finished jobs keep their checkpoint, the first
    unfinished one gets ``error`` (default: WorkerLost), the ones after it a ChainError (they
    were never run: no DONE.json, so the next run of the batch does them)."""
    out: list[dict] = []
    failed: Job | None = None
    for job in chain:
        r = finished_result(job, out_root) if failed is None else None
        if r is not None:
            out.append(r)
        elif failed is None:
            failed = job
            out.append(_record_failed(job, out_root,
                                      error or _worker_lost(attempts, before_start)))
        else:
            out.append(_record_failed(job, out_root, _chain_error(job, failed)))
    return out


def _chain_error(job: Job, prev: Job) -> str:
    return f"ChainError: previous run of site {job.site!r} failed ({prev.folder})"


# --------------------------------------------------------------------------------- ray
def run_ray(chains: list[list[Job]], out_root: str, stack_cfgs: dict, map_bundles: dict, *,
            address: str | None = None, workers: int | None = None,
            progress: Progress = None, code: str | None = None) -> list[dict]:
    """One Ray task per job. A chain is a sequence of task dependencies: task K receives task
    K-1's result ObjectRef (Ray waits for it and passes the value). Maps and parameter points
    are ``ray.put`` once and shared by every job that uses them. ``address`` goes to
    ``ray.init`` (None: a local instance with ``num_cpus=workers``); an already initialised
    Ray (e.g. a test's) is used as is.

    A task whose worker dies is retried by Ray (``max_retries=RAY_MAX_RETRIES``); one that
    still fails (retries used up, node lost) is recorded ``failed`` here and its chain's later
    tasks, which Ray fails with it, as ChainError."""
    from gatmo.errors import require

    ray = require("ray", "ray")
    started = False
    if not ray.is_initialized():
        kw: dict = {"log_to_driver": False}
        if address is None:
            kw.update(num_cpus=workers or os.cpu_count() or 1, include_dashboard=False)
        ray.init(address=address, **kw)
        started = True
    try:
        task = ray.remote(max_retries=RAY_MAX_RETRIES, retry_exceptions=False)(_ray_job)
        map_refs = {name: ray.put(b) for name, b in map_bundles.items()}
        cfg_refs = {h: ray.put(c) for h, c in stack_cfgs.items()}
        job_of: dict = {}
        for ch in chains:
            prev = None
            for job in ch:
                prev = task.remote(job, out_root, map_refs.get(job.map_name),
                                   cfg_refs.get(job.point_hash), prev, code)
                job_of[prev] = job
        total = len(job_of)
        got: dict[str, dict] = {}
        errors: dict[str, BaseException] = {}
        pending = list(job_of)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                job = job_of[ref]
                try:
                    got[job.id] = ray.get(ref)
                except Exception as exc:  # noqa: BLE001 - retries used up, or Ray's own error
                    errors[job.id] = exc
            if progress is not None:
                progress(len(got) + len(errors), total)
        for ch in chains:  # in chain order: a task failed by its predecessor is a ChainError
            failed_prev: Job | None = None
            for job in ch:
                if job.id in errors:
                    err = (_chain_error(job, failed_prev) if failed_prev is not None
                           else _ray_error(ray, errors[job.id]))
                    got[job.id] = _record_failed(job, out_root, err)
                failed_prev = job if got[job.id]["status"] == "failed" else None
        return [got[j.id] for ch in chains for j in ch]
    finally:
        if started:
            ray.shutdown()


def _ray_error(ray, exc: BaseException) -> str:
    lost = tuple(getattr(ray.exceptions, n) for n in
                 ("WorkerCrashedError", "OutOfMemoryError", "NodeDiedError")
                 if hasattr(ray.exceptions, n))
    if isinstance(exc, lost):
        return (f"WorkerLost: the worker process died while running this job "
                f"({1 + RAY_MAX_RETRIES} attempts; {type(exc).__name__})")
    return _one_line(exc)


def _ray_job(job: Job, out_root: str, bundle, stack_cfg, prev, code=None):
    from gatmo.batch.jobs import stale_worker

    if stale_worker(code):
        # Ray keeps a driver's workers between batches: one holding older gatmo modules exits,
        # and Ray's retry runs the job in a fresh worker importing the batch's sources
        os._exit(75)
    # a Ray task holds one CPU: numba's parallel kernels get one thread in it
    try:
        import numba

        numba.set_num_threads(1)
    except ImportError:  # pragma: no cover - numba is a core dependency
        pass
    return run_job(job, out_root, map_bundle_=bundle, stack_cfg=stack_cfg, prev=prev, code=code)


__all__ = ["LOCAL_MAX_RETRIES", "MAX_RETRIES", "RAY_MAX_RETRIES", "run_local", "run_ray"]
