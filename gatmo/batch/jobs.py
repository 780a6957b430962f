"""Executing one job (or one chain of jobs) into its own folder.

A job's folder is its checkpoint: ``DONE.json`` (the summary row) is written last and
atomically, so a folder with ``DONE.json`` is finished and a re-run skips it; a folder without
it is cleared and redone. A job that raises writes ``FAILED.json`` (error type and one-line
message) and returns a ``failed`` result instead of raising, so the batch goes on.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

import yaml

from gatmo._io import atomic_write_bytes, atomic_write_text
from gatmo.batch.spec import Job

DONE = "DONE.json"
FAILED = "FAILED.json"
# the parameter point as a full stack config (run_gatmo itself writes config.yaml)
STACK_YAML = "stack.yaml"


# --------------------------------------------------------------------------- map bundles
def map_bundle(map_yaml: str) -> dict:
    """The map YAML and its image as bytes, so that workers without the file (other cluster
    nodes) can rebuild it; put in Ray's object store once per map."""
    from gatmo.config import read_yaml

    p = Path(map_yaml)
    data, _ = read_yaml(p)
    files = {p.name: p.read_bytes()}
    image = data.get("image") if isinstance(data, dict) else None
    if image:
        ip = Path(image) if Path(image).is_absolute() else p.parent / image
        if ip.is_file() and not Path(image).is_absolute():
            files[image] = ip.read_bytes()
    return {"yaml": p.name, "files": files, "origin": str(p)}


def materialize_map(map_yaml: str, bundle: dict | None) -> str:
    """``map_yaml`` itself when readable here, else the bundle written to a local cache."""
    if bundle is None or Path(map_yaml).is_file():
        return map_yaml
    digest = hashlib.sha256(b"".join(bundle["files"].values())).hexdigest()[:16]
    folder = Path(tempfile.gettempdir()) / "gatmo-batch-maps" / digest
    for name, data in bundle["files"].items():
        if not (folder / name).is_file():
            atomic_write_bytes(folder / name, data)
    return str(folder / bundle["yaml"])


# --------------------------------------------------------------------------- code version
def source_fingerprint(root: str | Path | None = None) -> str:
    """A hash of gatmo's source files (relative path and bytes; about 1 ms).

    A batch runs on one version of the code: the driver takes this when the batch starts and
    every job is checked against it (:func:`code_error`). Workers import job code when they
    start their first jobs, during the batch, so an edit of the sources under a running batch
    (or a cluster worker with another gatmo installed) would otherwise go unnoticed - jobs
    mixing versions, or failing on a half-edited module with an error that names neither."""
    if root is None:
        import gatmo

        root = Path(gatmo.__file__).parent
    root = Path(root)
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        try:
            data = p.read_bytes()
        except OSError:  # removed while walking: a change as well
            continue
        h.update(f"{p.relative_to(root)}:{len(data)}\n".encode())
        h.update(data)
    return h.hexdigest()[:16]


# this process's gatmo sources when it started its first job, and why it cannot run jobs
# of the batch any more (its modules were imported while the sources changed)
_LOADED_CODE: str | None = None
_TAINTED: str | None = None


def _gatmo_modules() -> int:
    return sum(1 for m in sys.modules if m == "gatmo" or m.startswith("gatmo."))


def code_error(code: str | None) -> str | None:
    """Before a job: why this process must not run a job of a batch that started on ``code``
    (None: it may). A process holds the code of the sources when its first job started."""
    global _LOADED_CODE
    if code is None:
        return None
    if _LOADED_CODE is None:
        _LOADED_CODE = source_fingerprint()
    if _TAINTED is not None:
        return _TAINTED
    if _LOADED_CODE != code:
        return (f"CodeMismatch: this worker loaded gatmo sources {_LOADED_CODE}, the batch "
                f"started on {code} (edited since, or another install on the worker); "
                "re-run the batch")
    return None


def stale_worker(code: str | None) -> bool:
    """This process loaded other gatmo sources than the batch's ``code``, but the sources on
    disk are the batch's now: a fresh process would run the job right (a Ray worker kept from
    an earlier batch of the same driver, or one that imported during an edit)."""
    if code is None or (_LOADED_CODE is None and _TAINTED is None):
        return False
    return (_TAINTED is not None or _LOADED_CODE != code) and source_fingerprint() == code


def code_error_after(code: str | None, modules_before: int) -> str | None:
    """After a job that imported more gatmo modules: if the sources changed since this process
    loaded its first ones, it may now hold two versions - this job and all later ones in the
    process fail (a fresh process, e.g. the next run of the batch, does them)."""
    global _TAINTED
    if code is None or _gatmo_modules() == modules_before:
        return None
    now = source_fingerprint()
    if now != _LOADED_CODE:
        _TAINTED = (f"CodeChanged: gatmo's sources changed ({_LOADED_CODE} -> {now}) while "
                    "this worker was importing them; re-run the batch")
        return _TAINTED
    return None


# ------------------------------------------------------------------------------ results
def _result(job: Job, status: str, summary: dict | None = None, error: str | None = None,
            objects_path: str | None = None, seconds: float = 0.0) -> dict:
    return {"id": job.id, "status": status, "summary": summary or {}, "error": error,
            "objects_path": objects_path, "seconds": seconds, "folder": job.folder}


def finished_result(job: Job, out_root: str | Path) -> dict | None:
    """The result of an already finished job (DONE.json present), marked ``skipped``."""
    folder = Path(out_root) / job.folder
    done = folder / DONE
    if not done.is_file():
        return None
    try:
        data = json.loads(done.read_text())
    except (OSError, ValueError):
        return None  # a damaged checkpoint: redo the job
    if data.get("job") != job.id:
        return None  # same folder, other inputs (e.g. max_scans or the params file changed)
    obj = folder / "objects.json"
    return _result(job, "skipped", data.get("summary"), None,
                   str(obj) if obj.is_file() else None, float(data.get("seconds", 0.0)))


def run_job(job: Job, out_root: str | Path, *, map_bundle_: dict | None = None,
            stack_cfg: dict | None = None, prev: dict | None = None,
            code: str | None = None) -> dict:
    """Run one job into ``out_root/job.folder``; never raises for a job error.

    ``stack_cfg``: the parameter point as a stack config dict (None for ``echo``); ``prev``:
    the previous result of the chain (its ``objects_path`` seeds this run's object map);
    ``code``: the batch's :func:`source_fingerprint` (None: not checked)."""
    done = finished_result(job, out_root)
    if done is not None:
        return done
    folder = Path(out_root) / job.folder
    if folder.exists():  # outputs of an interrupted attempt: start clean
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    t0 = time.perf_counter()

    def fail(err: str, tb: str | None = None) -> dict:
        rec = {"job": job.id, "error": err} if tb is None else \
            {"job": job.id, "error": err, "traceback": tb}
        atomic_write_text(folder / FAILED, json.dumps(rec, indent=1))
        return _result(job, "failed", error=err, seconds=time.perf_counter() - t0)

    if prev is not None and prev["status"] == "failed":
        return fail(f"ChainError: previous run of site {job.site!r} failed ({prev['folder']})")
    err = code_error(code)
    if err is not None:
        return fail(err)
    objects_in = prev.get("objects_path") if prev is not None else None
    modules = _gatmo_modules()
    try:
        summary = _execute(job, folder, map_bundle_, stack_cfg, objects_in)
    except Exception as exc:  # noqa: BLE001 - every job error is recorded, the batch goes on
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        err = code_error_after(code, modules)  # a half-edited module explains the error
        err = f"{type(exc).__name__}: {msg}" + (f" ({err})" if err else "")
        return fail(err, traceback.format_exc())
    err = code_error_after(code, modules)
    if err is not None:
        return fail(err)
    seconds = time.perf_counter() - t0
    obj = folder / "objects.json"
    objects_path = str(obj) if obj.is_file() else None
    atomic_write_text(folder / DONE, json.dumps(
        {"job": job.id, "command": job.command, "map": job.map_yaml, "logs": list(job.logs),
         "point": [list(p) for p in job.point], "seed": job.seed, "seconds": seconds,
         "objects_in": objects_in, "summary": summary}, indent=1, default=str))
    return _result(job, "ok", summary, None, objects_path, seconds)


def run_chain(jobs: list[Job], out_root: str, map_bundles: dict | None = None,
              stack_cfgs: dict | None = None, code: str | None = None) -> list[dict]:
    """Run a chain in order, each job seeded with the previous one's objects (local backend:
    one task per chain, chains in parallel)."""
    out: list[dict] = []
    prev = None
    for job in jobs:
        prev = run_job(job, out_root, map_bundle_=(map_bundles or {}).get(job.map_name),
                       stack_cfg=(stack_cfgs or {}).get(job.point_hash), prev=prev, code=code)
        out.append(prev)
    return out


# ------------------------------------------------------------------------------ kinds
def _flatten(d: Any, prefix: str = "") -> dict:
    """Nested dicts -> {"a.b": number/str}; lists and paths are dropped (not summary numbers)."""
    out: dict = {}
    if isinstance(d, dict):
        for k, v in d.items():
            key = f"{prefix}.{k}" if prefix else str(k)
            if isinstance(v, dict):
                out.update(_flatten(v, key))
            elif isinstance(v, bool | int | float | str) or v is None:
                out[key] = v
    return out


def _execute(job: Job, folder: Path, bundle, stack_cfg, objects_in) -> dict:
    if job.command == "echo":
        return _echo(job, folder, objects_in)
    from gatmo.pipeline.config import load_stack_config

    stack_cfg = dict(stack_cfg or {})
    stack_cfg["seed"] = job.seed
    cfg_path = folder / STACK_YAML
    atomic_write_text(cfg_path, yaml.safe_dump(stack_cfg, sort_keys=False))
    map_yaml = materialize_map(job.map_yaml, bundle)
    if job.command == "localize":
        from gatmo.pipeline.localize import run_localize

        cfg = load_stack_config(cfg_path)
        s = run_localize(map_yaml, job.log, out_path=folder / "poses.tum", config=cfg.amcl,
                         max_scans=job.max_scans, seed=job.seed)
        return _flatten(s.as_dict())
    if job.command == "run":
        from gatmo.pipeline.runs import run_gatmo

        s = run_gatmo(map_yaml, job.log, folder, objects_path=objects_in, config_path=cfg_path,
                      run_id=job.chain_pos + 1, max_scans=job.max_scans)
        return _flatten(s.rows[0] if s.rows else {})
    if job.command == "compare":
        from gatmo.pipeline.runs import compare

        r = compare(map_yaml, list(job.logs), folder, config_path=cfg_path,
                    max_scans=job.max_scans, pictures=False)
        flat = _flatten(r.overall)
        # scans = scans per side; the batch throughput counts each log once per side
        flat["scans"] = int(sum(o.get("scans", 0) for o in r.overall.values()))
        return flat
    raise ValueError(f"unknown command {job.command!r}")  # pragma: no cover - spec validates


def _echo(job: Job, folder: Path, objects_in) -> dict:
    """Test aid: counts the log's lines, sleeps ``echo.sleep_s``, fails on ``echo.fail``;
    with a site it writes objects.json naming the objects file it received (chain check).

    Worker deaths: ``echo.kill: true`` SIGKILLs the process running the job on every attempt;
    ``echo.kill_once: DIR`` does so only while ``DIR/<job id>`` does not exist (it creates that
    file, holding the killed process id, just before), so the first attempt dies and a retry
    succeeds. ``echo.taint: true`` marks the process, once the job is done, as holding modules
    from changed sources (as :func:`code_error_after` would). The summary's ``pid`` is the
    process that finished the job."""
    global _TAINTED
    point = dict(job.point)
    if point.get("echo.sleep_s"):
        time.sleep(float(point["echo.sleep_s"]))
    if point.get("echo.fail"):
        raise RuntimeError(f"echo job asked to fail (seed {job.seed})\nsecond line")
    marker_dir = point.get("echo.kill_once")
    if marker_dir:
        marker = Path(str(marker_dir)) / job.id
        if not marker.exists():
            atomic_write_text(marker, str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)
    if point.get("echo.kill"):
        os.kill(os.getpid(), signal.SIGKILL)
    scans = sum(1 for _ in open(job.log, "rb"))  # noqa: SIM115
    if job.site is not None:
        atomic_write_text(folder / "objects.json",
                          json.dumps({"chain_pos": job.chain_pos, "objects_in": objects_in}))
    if point.get("echo.taint"):
        _TAINTED = "CodeChanged: marked by echo.taint"
    return {"scans": scans, "seed": job.seed, "objects_in": objects_in, "pid": os.getpid()}


__all__ = ["DONE", "FAILED", "finished_result", "map_bundle", "materialize_map", "run_chain",
           "run_job", "code_error", "source_fingerprint", "stale_worker"]
