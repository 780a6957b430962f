"""gatmo.batch with the real job kinds (localize, run, compare) on a small simulated hall."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gatmo.batch import run_batch
from gatmo.batch.results import read_table
from gatmo.batch.spec import expand_jobs


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    from gatmo.datasets.sim import simulate_scenario

    return simulate_scenario(tmp_path_factory.mktemp("sim"), runs=2, seed=3)


def _spec(folder: Path, command: str, grid: str = "{amcl.max_particles: [500, 1000]}") -> Path:
    p = folder / f"spec_{command}.yaml"
    p.write_text(f"""
maps: {{hall: map.yaml}}
logs: [{{map: hall, glob: "run_*.clf", site: hall}}]
command: {command}
grid: {grid}
seeds: [0]
max_scans: 60
""")
    return p


def test_localize_sweep_applies_the_grid(scenario, tmp_path):
    spec = _spec(Path(scenario.out_dir), "localize")
    res = run_batch(spec, tmp_path / "out", workers=2)
    assert (res.jobs, res.ok, res.failed) == (4, 4, 0)
    assert res.scans_per_s > 0
    rows = read_table(res.results_path)
    for r in rows:
        assert int(r["scans"]) == 60
        # the parameter point reached the filter: never more particles than the grid's max
        assert float(r["mean_particles"]) <= float(r["amcl.max_particles"])
        assert float(r["ate_rmse_m"]) < 0.5  # tracked, with the sim's initial pose
        poses = tmp_path / "out" / r["folder"] / "poses.tum"
        assert sum(1 for ln in poses.read_text().splitlines() if not ln.startswith("#")) == 60
    # read_table types the values the same way for parquet and CSV
    assert {r["amcl.max_particles"] for r in rows} == {500, 1000}
    small = [r["mean_particles"] for r in rows if r["amcl.max_particles"] == 500]
    big = [r["mean_particles"] for r in rows if r["amcl.max_particles"] == 1000]
    assert max(small) < min(big)


def test_a_preset_is_the_configuration_every_point_starts_from(scenario, tmp_path):
    # a fleet of simulated halls on AMCL's defaults hands GATMO nothing; `preset: sim` is the
    # simulator's configuration, the grid still applied on top, and the jobs are others
    from gatmo.pipeline.config import load_stack_config, sim_stack_config

    plain = _spec(Path(scenario.out_dir), "run", grid="{amcl.max_particles: [2500]}")
    preset = Path(scenario.out_dir) / "spec_preset.yaml"
    preset.write_text(plain.read_text().replace("max_scans: 60", "max_scans: 200")
                      + "preset: sim\n")
    plain.write_text(plain.read_text().replace("max_scans: 60", "max_scans: 200"))
    ids = {j.id for ch in expand_jobs(plain) for j in ch}
    assert ids.isdisjoint(j.id for ch in expand_jobs(preset) for j in ch)
    rows = {}
    for name, spec in (("plain", plain), ("preset", preset)):
        res = run_batch(spec, tmp_path / name, workers=1)
        assert res.failed == 0
        rows[name] = read_table(res.results_path)
    assert all(float(r["gatmo_trusted_fraction"]) == 0.0 for r in rows["plain"])
    assert all(float(r["gatmo_trusted_fraction"]) > 0.2 for r in rows["preset"])
    want = sim_stack_config()
    want.amcl.max_particles = 2500
    for r in rows["preset"]:
        assert load_stack_config(tmp_path / "preset" / r["folder"] / "config.yaml") == want


def test_run_chain_feeds_objects_to_the_next_run(scenario, tmp_path):
    spec = _spec(Path(scenario.out_dir), "run", grid="{}")
    res = run_batch(spec, tmp_path / "out", workers=1)
    assert (res.jobs, res.ok) == (2, 2)
    (chain,) = expand_jobs(spec)
    out = tmp_path / "out"
    first = json.loads((out / chain[0].folder / "DONE.json").read_text())
    second = json.loads((out / chain[1].folder / "DONE.json").read_text())
    assert first["objects_in"] is None
    assert second["objects_in"] == str(out / chain[0].folder / "objects.json")
    assert (out / chain[1].folder / "objects.json").is_file()
    # a second pass finds every checkpoint
    again = run_batch(spec, out, workers=1)
    assert (again.ok, again.skipped) == (0, 2)


def test_compare_job_and_a_failing_job_recorded(scenario, tmp_path):
    spec = _spec(Path(scenario.out_dir), "compare", grid="{amcl.max_particles: [500]}")
    res = run_batch(spec, tmp_path / "out", workers=1)
    assert res.ok == 1
    (row,) = read_table(res.results_path)
    assert int(row["static.logs"]) == 2 and int(row["gatmo.logs"]) == 2
    assert int(row["scans"]) == 2 * 2 * 60  # two logs, both sides
    # a log that is not a log fails its job only
    bad = Path(scenario.out_dir) / "broken"
    bad.mkdir(exist_ok=True)
    (bad / "run_9.clf").write_text("FLASER 3 1.0\n")
    (Path(scenario.out_dir) / "map2.yaml").write_text(
        (Path(scenario.out_dir) / "map.yaml").read_text())
    p = Path(scenario.out_dir) / "spec_mixed.yaml"
    p.write_text("""
maps: {hall: map.yaml}
logs:
  - {map: hall, glob: "run_1.clf"}
  - {map: hall, glob: "broken/run_9.clf", site: broken}
command: localize
max_scans: 20
""")
    res = run_batch(p, tmp_path / "mixed", workers=2)
    assert (res.ok, res.failed) == (1, 1)
    (f,) = res.failed_jobs
    assert f["folder"].startswith("localize/broken/")
    assert f["error"].split(":")[0] in ("FormatError", "DataError")


def test_ray_localize_sweep(scenario, tmp_path, ray_local, monkeypatch):
    spec = _spec(Path(scenario.out_dir), "localize", grid="{amcl.max_particles: [500, 800]}")
    puts = []
    real_put = ray_local.put
    monkeypatch.setattr(ray_local, "put",
                        lambda obj, **kw: puts.append(obj) or real_put(obj, **kw))
    res = run_batch(spec, tmp_path / "out", backend="ray")
    assert (res.jobs, res.ok, res.failed) == (4, 4, 0)
    # one map and two parameter points in the object store, each put once for the 4 jobs
    assert len(puts) == 3
    assert sum(1 for b in puts if "files" in b) == 1
    assert sorted(c["amcl"]["max_particles"] for c in puts if "amcl" in c) == [500, 800]
    rows = read_table(res.results_path)
    assert all(r["scans"] == 60 for r in rows)
    assert all(r["mean_particles"] <= r["amcl.max_particles"] for r in rows)
