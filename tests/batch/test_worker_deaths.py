"""A worker process killed mid-job: retried on both backends, given up on after the retries
(recorded failed, batch finished), never a hung batch. The echo job SIGKILLs its own process:
``echo.kill_once: DIR`` on the first attempt only (``DIR/<job id>`` holds the killed pid),
``echo.kill: true`` on every attempt."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gatmo.batch import backends, run_batch
from gatmo.batch.results import read_table
from gatmo.batch.spec import expand_jobs
from tests.batch.world import echo_world, write_spec


def _kill_once_world(tmp_path: Path) -> tuple[Path, Path]:
    echo_world(tmp_path, logs=("r1.log", "r2.log", "solo.log"), lines=(1, 2, 3))
    marks = tmp_path / "killed"
    spec = write_spec(tmp_path, f"""
maps: {{m: maps/m.yaml}}
logs:
  - {{map: m, glob: "logs/r*.log", site: s}}
  - {{map: m, glob: "logs/solo.log"}}
command: echo
grid: {{echo.kill_once: ["{marks}"]}}
""")
    return spec, marks


def _check_killed_once_then_done(spec: Path, out: Path, marks: Path, res) -> None:
    assert (res.jobs, res.ok, res.failed, res.skipped) == (3, 3, 0, 0)
    jobs = [j for c in expand_jobs(spec) for j in c]
    for job in jobs:
        killed = int((marks / job.id).read_text())  # the first attempt's process, killed
        done = json.loads((out / job.folder / "DONE.json").read_text())
        assert done["summary"]["pid"] != killed  # finished by another process: a retry
    # a worker the pool took down while it was writing its marker leaves the atomic write's
    # temporary file (a dot file) behind; its job is killed again on the retry
    assert sorted(p.name for p in marks.iterdir() if not p.name.startswith(".")) == \
        sorted(j.id for j in jobs)
    chain = next(c for c in expand_jobs(spec) if len(c) == 2)
    second = json.loads((out / chain[1].folder / "DONE.json").read_text())
    assert second["objects_in"] == str(out / chain[0].folder / "objects.json")
    assert sorted(r["scans"] for r in read_table(res.results_path)) == [1, 2, 3]


def _kill_always_world(tmp_path: Path) -> Path:
    echo_world(tmp_path, logs=("r1.log", "r2.log", "solo.log"), lines=(1, 2, 3))
    return write_spec(tmp_path, """
maps: {m: maps/m.yaml}
logs:
  - {map: m, glob: "logs/r*.log", site: s}
  - {map: m, glob: "logs/solo.log"}
command: echo
grid: {echo.kill: [false, true]}
""")


def _check_given_up(spec: Path, out: Path, res, attempts: int) -> None:
    # the killing point's 3 jobs fail, the others finish: the batch is not stopped
    assert (res.jobs, res.ok, res.failed) == (6, 3, 3)
    by_folder = {f["folder"]: f["error"] for f in res.failed_jobs}
    for chain in expand_jobs(spec):
        if not dict(chain[0].point)["echo.kill"]:
            continue
        first = by_folder[chain[0].folder]
        assert first.startswith("WorkerLost: the worker process died while running this job")
        assert f"({attempts} attempts" in first
        assert json.loads((out / chain[0].folder / "FAILED.json").read_text())["error"] == first
        if len(chain) == 2:  # never run: its input objects do not exist
            assert by_folder[chain[1].folder].startswith("ChainError: previous run of site 's'")
    meta = json.loads((out / "batch.json").read_text())
    assert meta["failed"] == 3 and len(meta["failed_jobs"]) == 3


# ------------------------------------------------------------------------------- local
def test_local_worker_killed_once_is_retried(tmp_path):
    spec, marks = _kill_once_world(tmp_path)
    out = tmp_path / "out"
    res = run_batch(spec, out, workers=2)
    _check_killed_once_then_done(spec, out, marks, res)


def test_local_single_worker_killed_once_is_retried(tmp_path):
    # one worker is still a pool process: the batch's own process is never the one killed
    spec, marks = _kill_once_world(tmp_path)
    out = tmp_path / "out"
    res = run_batch(spec, out, workers=1)
    _check_killed_once_then_done(spec, out, marks, res)


def test_local_worker_always_killed_is_recorded_failed(tmp_path, monkeypatch):
    monkeypatch.setattr(backends, "LOCAL_MAX_RETRIES", 1)
    spec = _kill_always_world(tmp_path)
    out = tmp_path / "out"
    res = run_batch(spec, out, workers=2)
    _check_given_up(spec, out, res, attempts=2)
    # the next run redoes only the failed jobs (and they die again)
    again = run_batch(spec, out, workers=2)
    assert (again.ok, again.failed, again.skipped) == (0, 3, 3)


def test_local_jobs_finished_before_a_death_keep_their_checkpoint(tmp_path):
    """Chain r1 -> r2 where only r2 kills its worker: r1 is not redone by the retry, and is
    counted as run now (ok), not skipped."""
    echo_world(tmp_path, logs=("r1.log", "r2.log"), lines=(1, 2))
    marks = tmp_path / "killed"
    spec = write_spec(tmp_path, f"""
maps: {{m: maps/m.yaml}}
logs: [{{map: m, glob: "logs/r*.log", site: s}}]
command: echo
grid: {{echo.kill_once: ["{marks}"]}}
""")
    (chain,) = expand_jobs(spec)
    marks.mkdir()
    (marks / chain[0].id).write_text("0")  # r1 behaves as if already killed once
    out = tmp_path / "out"
    res = run_batch(spec, out, workers=2)
    assert (res.ok, res.failed, res.skipped) == (2, 0, 0)
    first = json.loads((out / chain[0].folder / "DONE.json").read_text())
    second = json.loads((out / chain[1].folder / "DONE.json").read_text())
    assert int((marks / chain[1].id).read_text()) != second["summary"]["pid"]
    # r1 ran once, in the process later killed by r2 (one chain = one task)
    assert first["summary"]["pid"] == int((marks / chain[1].id).read_text())


# --------------------------------------------------------------------------------- ray
def test_ray_worker_killed_once_is_retried(tmp_path, ray_local):
    spec, marks = _kill_once_world(tmp_path)
    out = tmp_path / "out"
    res = run_batch(spec, out, backend="ray")
    _check_killed_once_then_done(spec, out, marks, res)


def test_ray_worker_always_killed_is_recorded_failed(tmp_path, ray_local, monkeypatch):
    monkeypatch.setattr(backends, "RAY_MAX_RETRIES", 1)
    spec = _kill_always_world(tmp_path)
    out = tmp_path / "out"
    res = run_batch(spec, out, backend="ray")
    _check_given_up(spec, out, res, attempts=2)


def test_ray_tasks_carry_max_retries(monkeypatch, ray_local):
    """The task options really are max_retries=RAY_MAX_RETRIES, retry_exceptions=False."""
    seen = {}
    real = ray_local.remote

    def remote(*args, **kw):
        seen.update(kw)
        return real(*args, **kw)

    monkeypatch.setattr(ray_local, "remote", remote)
    assert backends.run_ray([], "/nonexistent", {}, {}) == []
    assert seen == {"max_retries": backends.RAY_MAX_RETRIES, "retry_exceptions": False}
    assert backends.RAY_MAX_RETRIES >= 1


@pytest.mark.parametrize("workers", [1, 2])
def test_local_worker_dying_before_any_job_gives_up(tmp_path, monkeypatch, workers):
    """Workers that die before starting a job (here: every pool's initializer exits) are
    retried LOCAL_MAX_RETRIES times, then the jobs are recorded failed - no hang."""
    monkeypatch.setattr(backends, "LOCAL_MAX_RETRIES", 1)
    monkeypatch.setattr(backends, "_init_worker", _die)
    echo_world(tmp_path)
    spec = write_spec(tmp_path, "maps: {m: maps/m.yaml}\nlogs: [{map: m, glob: 'logs/*.log'}]\n"
                                "command: echo\n")
    res = run_batch(spec, tmp_path / "out", workers=workers)
    assert (res.ok, res.failed) == (0, 2)
    assert all(f["error"].startswith("WorkerLost: pool workers died before starting")
               for f in res.failed_jobs)


def _die(threads: int) -> None:
    import os

    os._exit(3)
