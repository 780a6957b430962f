"""gatmo.batch: spec expansion, local and Ray backends, checkpoints, failures, chains."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gatmo.batch import run_batch
from gatmo.batch.results import read_table
from gatmo.batch.spec import expand_jobs
from gatmo.errors import ConfigError

MAP_YAML = "image: m.pgm\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n" \
           "occupied_thresh: 0.65\nfree_thresh: 0.196\n"


def _echo_world(tmp: Path, logs=("a.log", "b.log"), lines=(3, 5)) -> Path:
    (tmp / "maps").mkdir()
    (tmp / "maps" / "m.yaml").write_text(MAP_YAML)
    (tmp / "maps" / "m.pgm").write_bytes(b"P5\n2 2\n255\n" + bytes(4))
    (tmp / "logs").mkdir()
    for name, n in zip(logs, lines, strict=True):
        (tmp / "logs" / name).write_text("x\n" * n)
    return tmp


def _spec(tmp: Path, text: str) -> Path:
    p = tmp / "spec.yaml"
    p.write_text(text)
    return p


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


def test_ray_backend_echo_sweep_with_chain(tmp_path):
    ray = pytest.importorskip("ray", reason="ray not installed: pip install 'gatmo[ray]'")
    _echo_world(tmp_path, logs=("r1.log", "r2.log"), lines=(2, 4))
    spec = _spec(tmp_path, """
maps: {m: maps/m.yaml}
logs: [{map: m, glob: "logs/r*.log", site: s}]
command: echo
grid: {echo.k: [1, 2]}
seeds: [0]
""")
    out = tmp_path / "out"
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        res = run_batch(spec, out, backend="ray")
        assert (res.jobs, res.ok, res.failed) == (4, 4, 0)
        for chain in expand_jobs(spec):
            d = json.loads((out / chain[1].folder / "DONE.json").read_text())
            assert d["objects_in"] == str(out / chain[0].folder / "objects.json")
        assert sorted(int(r["scans"]) for r in read_table(res.results_path)) == [2, 2, 4, 4]
    finally:
        ray.shutdown()


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
    rc = main(["batch", str(spec), "--out", str(tmp_path / "out"), "--workers", "1"])
    assert rc == 1  # half the jobs were told to fail
    text = capsys.readouterr().out
    assert "failed" in text
    assert (tmp_path / "out" / "batch.json").exists()
    rc = main(["batch", str(spec), "--out", str(tmp_path / "out"), "--workers", "1"])
    assert rc == 1  # failed jobs are redone and fail again; finished ones are skipped
    import json

    assert json.loads((tmp_path / "out" / "batch.json").read_text())["skipped"] > 0
