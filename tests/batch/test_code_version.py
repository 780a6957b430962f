"""A batch runs on one version of gatmo's sources: a worker holding other code (sources edited
under the batch, a Ray worker kept from an earlier batch, another install on a cluster node)
does not run its jobs silently - it says so, and a stale Ray worker is replaced."""

from __future__ import annotations

import json

import pytest

from gatmo.batch import jobs, run_batch
from gatmo.batch.spec import expand_jobs
from tests.batch.world import echo_world, write_spec


def _spec(tmp_path, grid="{}"):
    echo_world(tmp_path, logs=("a.log", "b.log", "c.log"), lines=(1, 2, 3))
    return write_spec(tmp_path, f"maps: {{m: maps/m.yaml}}\nlogs: [{{map: m, glob: 'logs/*.log'}}]"
                                f"\ncommand: echo\ngrid: {grid}\n")


def test_code_checks_in_one_process(monkeypatch):
    monkeypatch.setattr(jobs, "_LOADED_CODE", None)
    monkeypatch.setattr(jobs, "_TAINTED", None)
    disk = ["A"]
    monkeypatch.setattr(jobs, "source_fingerprint", lambda: disk[0])
    assert jobs.code_error(None) is None  # not checked
    assert jobs.code_error("A") is None  # loads "A" with its first job
    assert jobs.code_error("B").startswith("CodeMismatch: this worker loaded gatmo sources A")
    n = jobs._gatmo_modules()
    assert jobs.code_error_after("A", n) is None  # no new module imported: nothing to check
    assert jobs.code_error_after("A", n - 1) is None  # imported, sources unchanged
    assert not jobs.stale_worker("A")
    disk[0] = "B"  # edited while the process imports more modules for a job
    assert jobs.code_error_after("A", n - 1).startswith("CodeChanged: gatmo's sources changed")
    assert jobs.code_error("A").startswith("CodeChanged")  # every later job of the process
    assert jobs.stale_worker("B")  # a fresh process would load B
    assert not jobs.stale_worker("C")  # ... but not C


def test_source_fingerprint_is_the_bytes(tmp_path):
    (tmp_path / "pkg").mkdir()
    mod = tmp_path / "pkg" / "m.py"
    mod.write_text("x = 1\n")
    a = jobs.source_fingerprint(tmp_path)
    mod.touch()
    assert jobs.source_fingerprint(tmp_path) == a  # same bytes: same code
    mod.write_text("x = 2\n")
    assert jobs.source_fingerprint(tmp_path) != a
    assert len(jobs.source_fingerprint()) == 16  # gatmo's own sources


def test_local_workers_on_other_code_fail_their_jobs_clearly(tmp_path, monkeypatch):
    spec = _spec(tmp_path)
    out = tmp_path / "out"
    # the batch "started" on other sources than the workers import
    monkeypatch.setattr(jobs, "source_fingerprint", lambda: "0123456789abcdef")
    res = run_batch(spec, out, workers=2)
    assert (res.ok, res.failed) == (0, 3)
    assert all(f["error"].startswith("CodeMismatch: this worker loaded gatmo sources ")
               and "the batch started on 0123456789abcdef" in f["error"]
               for f in res.failed_jobs)
    monkeypatch.undo()
    again = run_batch(spec, out, workers=2)  # the sources are the batch's: all done
    assert (again.ok, again.failed, again.code_changed) == (3, 0, False)


def test_sources_changed_during_a_batch_are_reported(tmp_path, monkeypatch, capsys):
    from gatmo.cli import main

    spec = _spec(tmp_path)
    real = jobs.source_fingerprint()
    seen = iter([real, "edited-at-end"])  # driver: at the start, at the end
    monkeypatch.setattr(jobs, "source_fingerprint", lambda: next(seen))
    assert main(["batch", str(spec), "--out", str(tmp_path / "out"), "--workers", "1"]) == 0
    meta = json.loads((tmp_path / "out" / "batch.json").read_text())
    assert meta["code_changed"] is True
    assert meta["code_fingerprint"] == [real, "edited-at-end"]
    assert "source files changed while the batch ran" in capsys.readouterr().out


def test_ray_stale_worker_is_replaced(tmp_path, ray_local):
    """Each job marks its Ray worker as holding changed code once done; the next job given to
    that worker makes it exit, and Ray's retry runs the job in a fresh worker."""
    spec = _spec(tmp_path, grid="{echo.taint: [true]}")
    out = tmp_path / "out"
    res = run_batch(spec, out, backend="ray")
    assert (res.ok, res.failed) == (3, 0)
    pids = [json.loads((out / j.folder / "DONE.json").read_text())["summary"]["pid"]
            for c in expand_jobs(spec) for j in c]
    assert len(set(pids)) == 3  # no job ran in a worker an earlier job had marked


@pytest.fixture(autouse=True)
def _fresh_process_state(monkeypatch):
    # the test process runs no jobs itself, but keep its code state untouched by the tests
    monkeypatch.setattr(jobs, "_LOADED_CODE", jobs._LOADED_CODE)
    monkeypatch.setattr(jobs, "_TAINTED", jobs._TAINTED)
