"""gatmo.batch: spec expansion, local and Ray backends, checkpoints, failures, chains."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gatmo.batch import run_batch
from gatmo.batch.results import read_table
from gatmo.batch.spec import expand_jobs
from gatmo.errors import ConfigError
from tests.batch.world import MAP_YAML, echo_world, write_spec


def _echo_world(tmp: Path, logs=("a.log", "b.log"), lines=(3, 5)) -> Path:
    return echo_world(tmp, logs, lines)


def _spec(tmp: Path, text: str) -> Path:
    return write_spec(tmp, text)


def test_expansion_grid_globs_relative_paths_and_stable_ids(tmp_path):
    _echo_world(tmp_path)
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml}
logs:
  - {map: m, glob: "logs/*.log"}
command: echo
grid:
  echo.a: [1, 2, 3]
  echo.b: [x, y]
seeds: [0, 7]
""")
    chains = expand_jobs(spec)
    jobs = [j for c in chains for j in c]
    assert all(len(c) == 1 for c in chains)
    assert len(jobs) == 2 * 3 * 2 * 2  # logs x a x b x seeds
    assert {dict(j.point)["echo.a"] for j in jobs} == {1, 2, 3}
    assert len({j.id for j in jobs}) == len(jobs)
    assert len({j.folder for j in jobs}) == len(jobs)
    j = jobs[0]
    assert j.map_yaml == str((tmp_path / "maps" / "m.yaml").resolve())
    assert j.log == str((tmp_path / "logs" / "a.log").resolve())
    assert j.folder == f"echo/a/{j.point_hash}/seed0"
    # ids depend on the inputs only: the same spec expands to the same ids
    assert [x.id for c in expand_jobs(spec) for x in c] == [x.id for x in jobs]


def test_site_makes_a_chain_in_log_order(tmp_path):
    _echo_world(tmp_path, logs=("run_2.log", "run_1.log"), lines=(1, 1))
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml}
logs: [{map: m, glob: "logs/run_*.log", site: hall}]
command: run
seeds: [0, 1]
""")
    chains = expand_jobs(spec)
    assert len(chains) == 2  # one chain per seed
    assert [Path(j.log).name for j in chains[0]] == ["run_1.log", "run_2.log"]
    assert [j.chain_pos for j in chains[0]] == [0, 1]
    assert chains[0][1].folder.startswith("run/hall/")


@pytest.mark.parametrize(("text", "field", "line"), [
    ("maps: {m: maps/m.yaml}\nlogs: [{map: m, glob: 'logs/*.log'}]\ncommand: fly\n",
     "command", 3),
    ("maps: {m: maps/m.yaml}\nlogs: [{map: zz, glob: 'logs/*.log'}]\ncommand: echo\n",
     "logs.0.map", 2),
    ("maps: {m: maps/m.yaml}\nlogs: [{map: m, glob: 'nope/*.log'}]\ncommand: echo\n",
     "logs.0.glob", 2),
    ("maps: {m: maps/m.yaml}\nlogs: [{map: m, glob: 'logs/*.log'}]\ncommand: localize\n"
     "grid:\n  amcl.max_particls: [1]\n", "grid.amcl.max_particls", 5),
    ("maps: {m: maps/m.yaml}\nlogs: [{map: m, glob: 'logs/*.log'}]\ncommand: localize\n"
     "grid:\n  amcl.max_particles: [abc]\n", "grid.amcl.max_particles", 5),
    ("maps: {m: maps/m.yaml}\nlogs: [{map: m, glob: 'logs/*.log'}]\ncommand: echo\n"
     "seed: [1]\n", "seed", 4),
    ("maps: {m: maps/m.yaml}\nlogs: [{map: m, glob: 'logs/*.log'}]\ncommand: run\n"
     "preset: nope\n", "preset", 4),
])
def test_bad_spec_names_the_key(tmp_path, text, field, line):
    _echo_world(tmp_path)
    spec = _spec(tmp_path, text)
    with pytest.raises(ConfigError) as ei:
        expand_jobs(spec)
    assert ei.value.field == field
    assert ei.value.line == line
    assert ei.value.file == str(spec)


def test_local_echo_end_to_end_failures_and_rerun_skips(tmp_path):
    _echo_world(tmp_path)
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml}
logs: [{map: m, glob: "logs/*.log"}]
command: echo
grid: {echo.fail: [false, true]}
seeds: [0, 1]
""")
    out = tmp_path / "out"
    res = run_batch(spec, out, workers=2)
    assert (res.jobs, res.ok, res.failed, res.skipped) == (8, 4, 4, 0)
    rows = read_table(res.results_path)
    assert len(rows) == 8
    ok = [r for r in rows if r["status"] == "ok"]
    assert sorted(int(r["scans"]) for r in ok) == [3, 3, 5, 5]
    bad = [r for r in rows if r["status"] == "failed"]
    assert all(r["error"] == f"RuntimeError: echo job asked to fail (seed {r['seed']})"
               for r in bad)
    meta = json.loads((out / "batch.json").read_text())
    assert meta["failed"] == 4 and len(meta["failed_jobs"]) == 4
    folder = out / bad[0]["folder"]
    assert (folder / "FAILED.json").is_file() and not (folder / "DONE.json").exists()
    done = out / ok[0]["folder"] / "DONE.json"
    stamp = done.stat().st_mtime_ns
    res2 = run_batch(spec, out, workers=2)
    # finished jobs are skipped untouched; failed ones are tried again (and fail again)
    assert (res2.ok, res2.failed, res2.skipped) == (0, 4, 4)
    assert done.stat().st_mtime_ns == stamp
    rows2 = read_table(res2.results_path)
    assert sorted(int(r["scans"]) for r in rows2 if r["status"] == "skipped") == [3, 3, 5, 5]
    # changed inputs (max_scans is part of the job id) invalidate the checkpoints
    spec.write_text(spec.read_text() + "max_scans: 9\n")
    res3 = run_batch(spec, out, workers=1)
    assert (res3.ok, res3.failed, res3.skipped) == (4, 4, 0)


def test_chain_receives_previous_objects_and_resumes(tmp_path):
    _echo_world(tmp_path, logs=("r1.log", "r2.log"), lines=(1, 2))
    (tmp_path / "logs" / "r3.log").write_text("x\n")
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml}
logs: [{map: m, glob: "logs/r*.log", site: s}]
command: echo
""")
    out = tmp_path / "out"
    res = run_batch(spec, out, workers=2)
    assert res.ok == 3
    chain = expand_jobs(spec)[0]
    got = [json.loads((out / j.folder / "DONE.json").read_text())["objects_in"] for j in chain]
    assert got[0] is None
    assert got[1] == str(out / chain[0].folder / "objects.json")
    assert got[2] == str(out / chain[1].folder / "objects.json")
    # lose the last run: a re-run redoes only it, fed by the finished run 2
    import shutil

    shutil.rmtree(out / chain[2].folder)
    res2 = run_batch(spec, out, workers=1)
    assert (res2.ok, res2.skipped) == (1, 2)
    d = json.loads((out / chain[2].folder / "DONE.json").read_text())
    assert d["objects_in"] == str(out / chain[1].folder / "objects.json")


def test_chain_stops_after_a_failed_run(tmp_path):
    from gatmo.batch.jobs import run_chain

    _echo_world(tmp_path, logs=("r1.log", "r2.log"), lines=(1, 1))
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml}
logs: [{map: m, glob: "logs/r*.log", site: s}]
command: echo
grid: {echo.fail: [true]}
""")
    out = tmp_path / "out"
    res = run_chain(expand_jobs(spec)[0], str(out))
    assert [r["status"] for r in res] == ["failed", "failed"]
    assert res[1]["error"].startswith("ChainError")


def test_ray_backend_echo_sweep_with_chain(tmp_path, ray_local, monkeypatch):
    ray = ray_local
    _echo_world(tmp_path, logs=("r1.log", "r2.log"), lines=(2, 4))
    (tmp_path / "maps" / "n.yaml").write_text(MAP_YAML)
    (tmp_path / "logs" / "solo.log").write_text("x\n" * 3)
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml, n: maps/n.yaml}
logs:
  - {map: m, glob: "logs/r*.log", site: s}
  - {map: n, glob: "logs/solo.log"}
command: echo
grid: {echo.k: [1, 2], echo.fail: [false, true]}
seeds: [0]
""")
    puts = []
    real_put = ray.put
    monkeypatch.setattr(ray, "put", lambda obj, **kw: puts.append(obj) or real_put(obj, **kw))
    out = tmp_path / "out"
    res = run_batch(spec, out, backend="ray")
    # 4 points x (a chain of 2 + 1 solo job); failing points fail both runs of their chain
    assert (res.jobs, res.ok, res.failed) == (12, 6, 6)
    # each map is put in the object store once, not once per job (echo jobs have no stack
    # config to put; test_ray_localize_sweep counts those)
    assert len(puts) == 2
    assert sorted(b["yaml"] for b in puts) == ["m.yaml", "n.yaml"]
    chains = expand_jobs(spec)
    for chain in chains:
        if len(chain) == 2 and not dict(chain[0].point)["echo.fail"]:
            d = json.loads((out / chain[1].folder / "DONE.json").read_text())
            assert d["objects_in"] == str(out / chain[0].folder / "objects.json")
    rows = read_table(res.results_path)
    assert sorted(r["scans"] for r in rows if r["status"] == "ok") == [2, 2, 3, 3, 4, 4]
    errors = sorted(r["error"] for r in rows if r["status"] == "failed")
    assert sum(e.startswith("RuntimeError: echo job asked to fail") for e in errors) == 4
    assert sum(e.startswith("ChainError: previous run of site 's'") for e in errors) == 2


def test_materialize_map_rebuilds_a_missing_map(tmp_path):
    from gatmo.batch.jobs import map_bundle, materialize_map

    _echo_world(tmp_path)
    b = map_bundle(str(tmp_path / "maps" / "m.yaml"))
    p = materialize_map(str(tmp_path / "elsewhere" / "m.yaml"), b)
    assert Path(p).read_text() == MAP_YAML
    assert (Path(p).parent / "m.pgm").read_bytes() == (tmp_path / "maps" / "m.pgm").read_bytes()


def test_ray_backend_without_ray_names_the_extra(tmp_path, monkeypatch):
    import sys

    from gatmo.errors import MissingExtraError

    _echo_world(tmp_path)
    spec = _spec(tmp_path, "maps: {m: maps/m.yaml}\nlogs: [{map: m, glob: 'logs/a.log'}]\n"
                           "command: echo\n")
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(MissingExtraError, match=r"pip install 'gatmo\[ray\]'"):
        run_batch(spec, tmp_path / "out", backend="ray")
    with pytest.raises(ConfigError, match="unknown backend"):
        run_batch(spec, tmp_path / "out", backend="slurm")


def test_cli_batch_runs_and_reports_failures(tmp_path, capsys):
    from gatmo.cli import main

    _echo_world(tmp_path)
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml}
logs:
  - {map: m, glob: "logs/*.log"}
command: echo
grid:
  echo.fail: [false, true]
""")
    out = tmp_path / "out"
    rc = main(["batch", str(spec), "--out", str(out), "--workers", "1"])
    assert rc == 1  # half the jobs were told to fail
    text = capsys.readouterr().out
    meta = json.loads((out / "batch.json").read_text())
    assert (meta["ok"], meta["failed"], meta["skipped"]) == (2, 2, 0)
    # batch.json and the CLI list every failed job: folder, log and error
    assert sorted(Path(f["log"]).name for f in meta["failed_jobs"]) == ["a.log", "b.log"]
    for f in meta["failed_jobs"]:
        assert f["error"] == "RuntimeError: echo job asked to fail (seed 0)"
        assert f"failed: {f['folder']}: {f['error']}" in text
        assert (out / f["folder"] / "FAILED.json").is_file()
    assert "batch.json" in text
    rc = main(["batch", str(spec), "--out", str(out), "--workers", "1"])
    assert rc == 1  # failed jobs are redone and fail again; finished ones are skipped
    meta = json.loads((out / "batch.json").read_text())
    assert (meta["ok"], meta["failed"], meta["skipped"]) == (0, 2, 2)
    assert len(meta["failed_jobs"]) == 2


def test_cli_batch_all_ok_exits_zero_and_lists_nothing(tmp_path, capsys):
    from gatmo.cli import main

    _echo_world(tmp_path)
    spec = _spec(tmp_path, "maps: {m: maps/m.yaml}\nlogs: [{map: m, glob: 'logs/*.log'}]\n"
                           "command: echo\n")
    assert main(["batch", str(spec), "--out", str(tmp_path / "out"), "--workers", "2"]) == 0
    assert "failed:" not in capsys.readouterr().out
    assert json.loads((tmp_path / "out" / "batch.json").read_text())["failed_jobs"] == []


def test_overlapping_globs_run_a_job_once_and_chains_must_not_overlap(tmp_path):
    _echo_world(tmp_path)
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml}
logs:
  - {map: m, glob: "logs/*.log"}
  - {map: m, glob: "logs/a.log"}
command: echo
""")
    jobs = [j for c in expand_jobs(spec) for j in c]
    assert sorted(Path(j.log).name for j in jobs) == ["a.log", "b.log"]
    spec.write_text("""
maps: {m: maps/m.yaml}
logs:
  - {map: m, glob: "logs/*.log", site: s}
  - {map: m, glob: "logs/a.log", site: s}
command: run
""")
    with pytest.raises(ConfigError, match="belongs to two chains"):
        expand_jobs(spec)


def test_checkpoints_follow_the_inputs_contents(tmp_path):
    """A job's id hashes the map and params files' bytes, each log's size and mtime and, in a
    chain, its predecessor's id: changing any of them redoes exactly the jobs it feeds."""
    import os

    _echo_world(tmp_path, logs=("r1.log", "r2.log", "solo.log"), lines=(1, 2, 3))
    (tmp_path / "p.yaml").write_text("laser_max_beams: 30\n")
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml}
params: p.yaml
logs:
  - {map: m, glob: "logs/r*.log", site: s}
  - {map: m, glob: "logs/solo.log"}
command: echo
""")
    out = tmp_path / "out"
    assert run_batch(spec, out, workers=1).ok == 3
    assert run_batch(spec, out, workers=1).skipped == 3
    # the first run of the chain changes: it and the run fed by its objects are redone
    log = tmp_path / "logs" / "r1.log"
    log.write_text("x\n" * 4)
    os.utime(log, ns=(log.stat().st_atime_ns, log.stat().st_mtime_ns + 10**9))
    res = run_batch(spec, out, workers=1)
    assert (res.ok, res.skipped) == (2, 1)
    assert sorted(r["scans"] for r in read_table(res.results_path)) == [2, 3, 4]
    # the params file's contents (same path) invalidate every job
    (tmp_path / "p.yaml").write_text("laser_max_beams: 60\n")
    assert run_batch(spec, out, workers=1).ok == 3
    # the map image's bytes too
    (tmp_path / "maps" / "m.pgm").write_bytes(b"P5\n2 2\n255\n" + bytes([255] * 4))
    assert run_batch(spec, out, workers=1).ok == 3
    assert run_batch(spec, out, workers=1).skipped == 3


def test_source_fingerprint_sees_an_edit(tmp_path):
    from gatmo.batch.jobs import source_fingerprint

    (tmp_path / "pkg").mkdir()
    mod = tmp_path / "pkg" / "m.py"
    mod.write_text("x = 1\n")
    a = source_fingerprint(tmp_path)
    assert source_fingerprint(tmp_path) == a
    mod.write_text("x = 22\n")
    assert source_fingerprint(tmp_path) != a
    assert len(source_fingerprint()) == 16  # gatmo's own sources


def test_ray_address_connects_without_local_resources(tmp_path, monkeypatch):
    """--address ray://HEAD:10001 goes to ray.init as is, without num_cpus (refused when
    joining a cluster) or dashboard options; no address starts a local instance."""
    ray = pytest.importorskip("ray", reason="ray not installed (the ray extra)")
    from gatmo.batch import backends

    calls = []

    class Stop(Exception):
        pass

    def fake_init(address=None, **kw):
        calls.append((address, kw))
        raise Stop

    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", fake_init)
    with pytest.raises(Stop):
        backends.run_ray([], str(tmp_path), {}, {}, address="ray://head:10001", workers=8)
    with pytest.raises(Stop):
        backends.run_ray([], str(tmp_path), {}, {}, workers=3)
    assert calls == [("ray://head:10001", {"log_to_driver": False}),
                     (None, {"log_to_driver": False, "num_cpus": 3,
                             "include_dashboard": False})]
