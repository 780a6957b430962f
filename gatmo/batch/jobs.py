"""Executing one job (or one chain of jobs) into its own folder.

A job's folder is its checkpoint: ``DONE.json`` (the summary row) is written last and
atomically, so a folder with ``DONE.json`` is finished and a re-run skips it; a folder without
it is cleared and redone. A job that raises writes ``FAILED.json`` (error type and one-line
message) and returns a ``failed`` result instead of raising, so the batch goes on.
"""

from __future__ import annotations

import hashlib
import json
import shutil
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
            stack_cfg: dict | None = None, prev: dict | None = None) -> dict:
    """Run one job into ``out_root/job.folder``; never raises for a job error.

    ``stack_cfg``: the parameter point as a stack config dict (None for ``echo``); ``prev``:
    the previous result of the chain (its ``objects_path`` seeds this run's object map)."""
    done = finished_result(job, out_root)
    if done is not None:
        return done
    folder = Path(out_root) / job.folder
    if folder.exists():  # outputs of an interrupted attempt: start clean
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    t0 = time.perf_counter()
    if prev is not None and prev["status"] == "failed":
        err = f"ChainError: previous run of site {job.site!r} failed ({prev['folder']})"
        atomic_write_text(folder / FAILED, json.dumps({"job": job.id, "error": err}))
        return _result(job, "failed", error=err, seconds=0.0)
    objects_in = prev.get("objects_path") if prev is not None else None
    try:
        summary = _execute(job, folder, map_bundle_, stack_cfg, objects_in)
    except Exception as exc:  # noqa: BLE001 - every job error is recorded, the batch goes on
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        err = f"{type(exc).__name__}: {msg}"
        atomic_write_text(folder / FAILED, json.dumps(
            {"job": job.id, "error": err, "traceback": traceback.format_exc()}, indent=1))
        return _result(job, "failed", error=err, seconds=time.perf_counter() - t0)
    seconds = time.perf_counter() - t0
    obj = folder / "objects.json"
    objects_path = str(obj) if obj.is_file() else None
    atomic_write_text(folder / DONE, json.dumps(
        {"job": job.id, "command": job.command, "map": job.map_yaml, "logs": list(job.logs),
         "point": [list(p) for p in job.point], "seed": job.seed, "seconds": seconds,
         "objects_in": objects_in, "summary": summary}, indent=1, default=str))
    return _result(job, "ok", summary, None, objects_path, seconds)


def run_chain(jobs: list[Job], out_root: str, map_bundles: dict | None = None,
              stack_cfgs: dict | None = None) -> list[dict]:
    """Run a chain in order, each job seeded with the previous one's objects (local backend:
    one task per chain, chains in parallel)."""
    out: list[dict] = []
    prev = None
    for job in jobs:
        prev = run_job(job, out_root, map_bundle_=(map_bundles or {}).get(job.map_name),
                       stack_cfg=(stack_cfgs or {}).get(job.point_hash), prev=prev)
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
    with a site it writes objects.json naming the objects file it received (chain check)."""
    point = dict(job.point)
    if point.get("echo.sleep_s"):
        time.sleep(float(point["echo.sleep_s"]))
    if point.get("echo.fail"):
        raise RuntimeError(f"echo job asked to fail (seed {job.seed})\nsecond line")
    scans = sum(1 for _ in open(job.log, "rb"))  # noqa: SIM115
    if job.site is not None:
        atomic_write_text(folder / "objects.json",
                          json.dumps({"chain_pos": job.chain_pos, "objects_in": objects_in}))
    return {"scans": scans, "seed": job.seed, "objects_in": objects_in}


__all__ = ["DONE", "FAILED", "finished_result", "map_bundle", "materialize_map", "run_chain",
           "run_job"]
