"""``gatmo compare`` and ``gatmo run`` end to end on a small simulated scenario, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gatmo.cli import main
from gatmo.datasets.sim import SimConfig, simulate_scenario
from gatmo.maps.io import load_map
from gatmo.maps.object_io import load_objects


@pytest.fixture(scope="module")
def scen(tmp_path_factory):
    cfg = SimConfig.for_preset("hall")
    cfg.robot.duration_s = 20.0
    return simulate_scenario(tmp_path_factory.mktemp("s"), runs=2, seed=5, config=cfg)


def test_compare_writes_summary_pictures_and_both_sides(scen, tmp_path, capsys):
    out = tmp_path / "cmp"
    rc = main(["compare", *map(str, scen.logs), "--map", str(scen.map_yaml), "--out", str(out),
               "--scenario", str(scen.scenario_json)])
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert {r["side"] for r in s["logs"]} == {"static", "gatmo"} and len(s["logs"]) == 4
    for r in s["logs"]:
        assert r["ate_rmse_m"] < 5.0 and 0 <= r["lost_fraction"] <= 1
    assert all(p.endswith(".png") for p in s["pictures"]) and len(s["pictures"]) == 6
    for p in s["pictures"]:
        assert (tmp_path / p).exists() or __import__("pathlib").Path(p).exists()
    objs = load_objects(out / "gatmo" / "02_run_2" / "objects.json")
    assert len(objs.objects) > 5
    assert load_map(out / "gatmo" / "02_run_2" / "map.yaml").cells.shape == \
        load_map(scen.map_yaml).cells.shape
    out = capsys.readouterr().out
    assert "static localizer vs gatmo" in out
    # given the scenario, the pieces moved and found, per log and over all
    full = [r for r in s["logs"] if r["side"] == "gatmo"]
    assert s["overall"]["gatmo"]["obj_moved"] == sum(r["obj_moved"] for r in full) > 0
    assert s["overall"]["gatmo"]["obj_found"] == sum(r["obj_found"] for r in full)
    assert "obj_moved" not in s["overall"]["static"]
    assert "moved" in out and "found" in out


def test_run_writes_poses_objects_map_events_and_continues_from_objects(scen, tmp_path):
    out1 = tmp_path / "r1"
    assert main(["run", "--map", str(scen.map_yaml), "--log", str(scen.logs[0]),
                 "--out", str(out1)]) == 0
    for name in ("poses.tum", "objects.json", "map.yaml", "map.pgm", "events.jsonl",
                 "config.yaml"):
        assert (out1 / name).exists(), name
    out2 = tmp_path / "r2"
    assert main(["run", "--map", str(scen.map_yaml), "--log", str(scen.logs[1]),
                 "--objects", str(out1 / "objects.json"), "--out", str(out2)]) == 0
    first, second = load_objects(out1 / "objects.json"), load_objects(out2 / "objects.json")
    assert {o.id for o in first.objects} <= {o.id for o in second.objects}  # identities kept
    # the run started from the first run's objects is run 2, in the file and in its events
    assert (first.runs, second.runs) == (1, 2)
    events = [json.loads(line) for line in (out2 / "events.jsonl").read_text().splitlines()]
    assert all(e["run"] == 2 for e in events)


def test_objects_made_on_another_map_are_refused(scen, tmp_path, capsys):
    # an objects.json records the map it was made on; given with another map (here the same
    # map padded by a column), its poses and cells would be in the wrong frame
    from gatmo.maps.io import save_map

    out1 = tmp_path / "r1"
    assert main(["run", "--map", str(scen.map_yaml), "--log", str(scen.logs[0]),
                 "--out", str(out1), "--max-scans", "5"]) == 0
    grid = load_map(scen.map_yaml)
    grid.cells = np.pad(grid.cells, ((0, 0), (0, 1)), constant_values=-1)
    other = tmp_path / "other.yaml"
    save_map(grid, other)
    rc = main(["run", "--map", str(other), "--log", str(scen.logs[1]), "--objects",
               str(out1 / "objects.json"), "--out", str(tmp_path / "r2"), "--max-scans", "5"])
    err = capsys.readouterr().err
    assert rc == 1 and "objects.json" in err and "base_map.shape" in err
    assert "Traceback" not in err


def test_unreadable_log_in_the_middle_keeps_earlier_results(scen, tmp_path, capsys):
    bad = tmp_path / "broken.clf"
    bad.write_text("FLASER 3 1.0 2.0\n")
    out = tmp_path / "cmp"
    rc = main(["compare", str(scen.logs[0]), str(bad), "--map", str(scen.map_yaml),
               "--out", str(out)])
    assert rc == 1
    err = capsys.readouterr().err
    assert "broken.clf" in err and "Traceback" not in err
    s = json.loads((out / "summary.json").read_text())
    assert len(s["logs"]) == 2  # the first log's two sides are kept


def test_ground_truth_that_does_not_match_is_refused(scen, tmp_path, capsys):
    gt = tmp_path / "gt.tum"
    gt.write_text("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n")
    rc = main(["compare", str(scen.logs[0]), "--map", str(scen.map_yaml), "--out",
               str(tmp_path / "c"), "--ground-truth", str(gt)])
    assert rc == 1 and "gt.tum" in capsys.readouterr().err


def test_log_that_does_not_overlap_the_map_is_refused(scen, tmp_path, capsys):
    rc = main(["compare", str(scen.logs[0]), "--map", str(scen.map_yaml), "--out",
               str(tmp_path / "c"), "--initial-pose", "500,500,0"])
    assert rc == 1
    err = capsys.readouterr().err
    assert "does not overlap the map" in err or "outside the map" in err


def _shifted_map(scen, tmp_path, dx_m: float):
    """The scenario's map with its origin moved by ``dx_m`` along x: the same walls, in a frame
    the log's own ground truth is not in (as Stage's is not in a map_server map's)."""
    import shutil

    import yaml

    meta = yaml.safe_load(scen.map_yaml.read_text())
    meta["origin"][0] += dx_m
    shutil.copy(scen.map_yaml.parent / meta["image"], tmp_path / meta["image"])
    out = tmp_path / "shifted.yaml"
    out.write_text(yaml.safe_dump(meta))
    return out


def test_ground_truth_in_another_frame_is_not_scored_against(scen, tmp_path, capsys):
    from gatmo.datasets.tum import read_tum, write_tum

    shifted = _shifted_map(scen, tmp_path, 50.0)
    log = str(scen.logs[0])
    # the start taken from the log's ground truth lands off the map: say where it came from
    assert main(["localize", "--map", str(shifted), "--log", log, "--out",
                 str(tmp_path / "p.tum")]) == 1
    err = capsys.readouterr().err
    assert "the log's first ground-truth pose (3.50 m, 7.00 m, -90.0 deg)" in err
    assert "another frame" in err and "--initial-pose" in err and "--global" in err
    # the given start in the map's frame runs; the log's ground truth is not scored against
    t, gt = read_tum(scen.gt[0])
    start = f"{gt[0, 0] + 50.0},{gt[0, 1]},{gt[0, 2]}"
    assert main(["localize", "--map", str(shifted), "--log", log, "--initial-pose", start,
                 "--out", str(tmp_path / "p.tum")]) == 0
    out = capsys.readouterr().out
    assert "warning:" in out and "not in the map's frame" in out and "ate_rmse_m" not in out
    p_t, p = read_tum(tmp_path / "p.tum")  # AMCL's defaults in a rearranged hall: tenths
    assert np.median(np.hypot(p[:, 0] - 50.0 - gt[:, 0], p[:, 1] - gt[:, 1])) < 0.5
    # a ground-truth file in the other frame is refused, naming it; one in the map's is scored
    cmp = ["compare", log, "--map", str(shifted), "--initial-pose", start]
    assert main([*cmp, "--ground-truth", str(scen.gt[0]), "--out", str(tmp_path / "a")]) == 1
    err = capsys.readouterr().err
    assert scen.gt[0].name in err and "not in the map's frame" in err
    moved = tmp_path / "gt_map.tum"
    write_tum(moved, t, gt + [50.0, 0.0, 0.0])
    assert main([*cmp, "--ground-truth", str(moved), "--out", str(tmp_path / "b")]) == 0
    s = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert not any("frame" in w for w in s["warnings"])
    assert all(r["ate_median_m"] < 0.5 for r in s["logs"])
    # without a file the in-log ground truth is dropped with a warning in summary.json
    assert main([*cmp, "--out", str(tmp_path / "c")]) == 0
    s = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert any("not in the map's frame" in w for w in s["warnings"])
    assert all("ate_rmse_m" not in r for r in s["logs"])
    # localize and run take --ground-truth too, refused or scored the same way
    capsys.readouterr()
    loc = ["localize", "--map", str(shifted), "--log", log, "--initial-pose", start,
           "--out", str(tmp_path / "q.tum")]
    assert main([*loc, "--ground-truth", str(moved)]) == 0
    out = capsys.readouterr().out
    assert "ate_rmse_m" in out and "warning" not in out
    assert main(["run", "--map", str(shifted), "--log", log, "--initial-pose", start,
                 "--ground-truth", str(scen.gt[0]), "--out", str(tmp_path / "r")]) == 1
    assert scen.gt[0].name in capsys.readouterr().err


def test_vet_ground_truth_keeps_ground_truth_that_puts_the_scans_on_the_map():
    from gatmo.errors import DataError
    from gatmo.pipeline.runs import GroundTruth, vet_ground_truth
    from tests.helpers import make_scan, room_grid

    grid = room_grid(10.0, 8.0, boxes=[(3.0, 3.0, 4.0, 4.0)])
    poses = np.array([[2.0 + 0.1 * i, 2.0, 0.3] for i in range(20)])
    scans = [make_scan(grid, p, max_range_m=4.0, stamp_s=0.1 * i) for i, p in enumerate(poses)]
    stamps = np.array([s.stamp_s for s in scans])
    right = GroundTruth(stamps, poses, "log (in-log)", in_log=True)
    assert vet_ground_truth(grid, scans, right, "log") == (right, [])
    assert vet_ground_truth(grid, scans, None, "log") == (None, [])
    off = poses + [0.0, 30.0, 0.0]
    in_log = GroundTruth(stamps, off, "log (in-log)", in_log=True)
    gt, warned = vet_ground_truth(grid, scans, in_log, "log")
    assert gt is None and len(warned) == 1 and warned[0].startswith("log: ")
    with pytest.raises(DataError, match="gt.tum.*not in the map's frame"):
        vet_ground_truth(grid, scans, GroundTruth(stamps, off, "gt.tum"), "log")


def test_simulate_writes_the_matched_stack_config_and_compare_warns_without_it(tmp_path,
                                                                              capsys):
    # a user's path: gatmo simulate, then gatmo compare on what it wrote. AMCL's defaults
    # (alphas 0.2, a flat model, a 0.5 m initial cloud) never let the cloud pass GATMO's
    # strict test in a simulated hall, so the full stack is the static localizer to the digit;
    # the stack.yaml the scenario carries (the simulated robot's odometry noise) does
    from gatmo.pipeline.config import load_stack_config, sim_stack_config
    from gatmo.pipeline.runs import simulate

    cfg = SimConfig.for_preset("hall")
    cfg.robot.duration_s = 20.0
    scen, stack_yaml = simulate(tmp_path / "s", runs=1, seed=5, sim_config=cfg)
    assert stack_yaml == scen.out_dir / "stack.yaml"
    assert load_stack_config(stack_yaml) == sim_stack_config()
    # a simulator whose wheels are noisier: the scenario's filter assumes its alphas
    noisy = cfg.model_copy(deep=True)
    noisy.odom.alpha1, noisy.odom.alpha3 = 0.1, 0.08
    _, noisy_yaml = simulate(tmp_path / "noisy", runs=1, seed=5, sim_config=noisy)
    a = load_stack_config(noisy_yaml).amcl
    assert (a.alpha1, a.alpha2, a.alpha3, a.alpha4) == (0.1, 0.01, 0.08, 0.01)
    args = [str(scen.logs[0]), "--map", str(scen.map_yaml), "--scenario",
            str(scen.scenario_json)]
    capsys.readouterr()
    assert main(["compare", *args, "--out", str(tmp_path / "plain")]) == 0
    out = capsys.readouterr().out
    plain = json.loads((tmp_path / "plain" / "summary.json").read_text())
    static, full = plain["logs"]
    assert full["gatmo_trusted_fraction"] == 0.0 and "gatmo_trusted_fraction" not in static
    assert full["ate_rmse_m"] == static["ate_rmse_m"]
    assert len(plain["warnings"]) == 1 and plain["warnings"][0].startswith("run_1.clf: ")
    assert "warning: run_1.clf: GATMO was handed 0 of" in out and "stack.yaml" in out

    assert main(["compare", *args, "--config", str(stack_yaml), "--out",
                 str(tmp_path / "matched")]) == 0
    out = capsys.readouterr().out
    matched = json.loads((tmp_path / "matched" / "summary.json").read_text())
    static, full = matched["logs"]
    assert full["gatmo_trusted_fraction"] > 0.2 and matched["warnings"] == []
    assert full["ate_rmse_m"] < static["ate_rmse_m"] < plain["logs"][0]["ate_rmse_m"]
    assert full["absent"] + full["relocated"] + full["added"] > 0
    assert "warning" not in out


DATA = __import__("pathlib").Path(__file__).resolve().parents[2].parent / "shared" / "data"


@pytest.mark.skipif(not (DATA / "slam-benchmark" / "intel.sort.bag").exists()
                    or not (DATA / "radish-corrected").exists(),
                    reason="../shared/data (the Intel log and its corrected poses) not found")
def test_real_intel_gatmo_acts_with_the_real_preset_and_warns_on_amcl_s_defaults(tmp_path,
                                                                               capsys):
    # the Intel lab, its first 600 scans, as a user runs it: AMCL's defaults never let the
    # cloud within GATMO's 0.1 m (README, "Real logs"), the real preset does
    from gatmo.pipeline.config import load_stack_config, real_stack_config
    from gatmo.pipeline.mapping import render_reference_map
    from gatmo.pipeline.runs import run_gatmo

    map_yaml = tmp_path / "map.yaml"
    render_reference_map(DATA / "radish-corrected" / "intel-corrected.log.gz", map_yaml)
    args = ["run", "--map", str(map_yaml), "--log", str(DATA / "slam-benchmark" /
            "intel.sort.bag"), "--initial-pose", "0.6,-0.03,-0.35", "--max-scans", "600"]
    assert main([*args, "--out", str(tmp_path / "amcl")]) == 0
    out = capsys.readouterr().out
    assert "warning: intel.sort.bag: GATMO was handed 0 of 600 scans" in out
    assert "--preset real" in out
    assert main([*args, "--preset", "real", "--out", str(tmp_path / "cli")]) == 0
    assert "warning" not in capsys.readouterr().out
    assert load_stack_config(tmp_path / "cli" / "config.yaml") == real_stack_config()
    res = run_gatmo(map_yaml, DATA / "slam-benchmark" / "intel.sort.bag", tmp_path / "real",
                    preset="real", initial_pose=[0.6, -0.03, -0.35], max_scans=600)
    assert res.warnings == [] and res.rows[0]["gatmo_trusted_fraction"] > 0.2
    # a preset or a file, not both
    assert main([*args, "--preset", "real", "--config", str(tmp_path / "cli" / "config.yaml"),
                 "--out", str(tmp_path / "both")]) == 1
    assert "not both" in capsys.readouterr().err


def test_untrusted_logs_names_each_full_stack_log_gatmo_got_no_trusted_scans_of():
    from gatmo.pipeline.config import StackConfig
    from gatmo.pipeline.runs import untrusted_logs

    rows = [{"log": "a.clf", "side": "static", "scans": 100},
            {"log": "a.clf", "side": "gatmo", "scans": 100, "gatmo_trusted_fraction": 0.3},
            {"log": "b.clf", "side": "gatmo", "scans": 200, "gatmo_trusted_fraction": 0.005},
            {"log": "c.clf", "side": "gatmo", "scans": 50, "gatmo_trusted_fraction": 0.0}]
    lines = untrusted_logs(rows, StackConfig())
    assert len(lines) == 2
    assert lines[0].startswith("b.clf: GATMO was handed 1 of 200 scans as trusted")
    assert lines[1].startswith("c.clf: GATMO was handed 0 of 50 scans as trusted")
    assert "within 0.1 m / 3 deg" in lines[1] and "--preset real" in lines[1]


def test_map_render_from_known_poses(scen, tmp_path):
    out = tmp_path / "m.yaml"
    assert main(["map", "render", str(scen.logs[0]), "--out", str(out)]) == 0
    m = load_map(out)
    truth = load_map(scen.map_yaml)
    occ = m.occupied_cells_world()
    assert len(occ) > 100
    assert np.mean(truth.value_at(occ) != 0) > 0.6  # mostly on mapped or moved things
    # the render section of a map-build configuration applies; --resolution replaces its cell
    cfg = tmp_path / "build.yaml"
    cfg.write_text("render:\n  occupied_thresh: 0.95\n")
    strict = tmp_path / "strict.yaml"
    assert main(["map", "render", str(scen.logs[0]), "--out", str(strict), "--config",
                 str(cfg)]) == 0
    # a cell needs about four hits more than misses, not one
    assert load_map(strict).occupied.sum() < 0.9 * m.occupied.sum()
    cfg.write_text("render:\n  resolution_m: 0.1\n")
    assert main(["map", "render", str(scen.logs[0]), "--out", str(strict), "--config",
                 str(cfg)]) == 0
    assert load_map(strict).resolution_m == pytest.approx(0.1)
    assert main(["map", "render", str(scen.logs[0]), "--out", str(strict), "--config",
                 str(cfg), "--resolution", "0.2"]) == 0
    assert load_map(strict).resolution_m == pytest.approx(0.2)


def test_traces_keep_the_poses_gatmo_was_given(scen, tmp_path):
    from gatmo.pipeline.config import sim_stack_config
    from gatmo.pipeline.runs import compare, load_scans

    res = compare(scen.map_yaml, scen.logs, tmp_path / "c", config=sim_stack_config(),
                  pictures=False, keep_traces=True)
    for k, log in enumerate(scen.logs):
        gt = np.array([s.gt_pose_xytheta for s in load_scans(log)])
        static, full = res.traces[(k, "static")], res.traces[(k, "gatmo")]
        assert np.isnan(static.gatmo_poses_xytheta).all()  # no GATMO on the static side
        given = full.gatmo_poses_xytheta
        trusted = np.isfinite(given[:, 0])
        # GATMO lays most scans of a simulated run from a trusted pose, and that pose is
        # the one it was handed: close to the truth
        assert 0.2 < trusted.mean() <= 1.0
        err = np.hypot(*(given[trusted, :2] - gt[trusted, :2]).T)
        assert np.median(err) < 0.1
        # the poses the scan-to-map alignment confirmed are a part of those, and closer still
        confirmed = full.gatmo_verified
        assert confirmed.any() and not (confirmed & ~trusted).any()
        assert np.array_equal(confirmed, full.align_outcomes == "confirmed")
        assert np.median(np.hypot(*(given[confirmed, :2] - gt[confirmed, :2]).T)) < 0.05
        assert not static.gatmo_verified.any() and (static.align_outcomes == "").all()


@pytest.mark.parametrize("preset", ["hall", "office"])
def test_the_simulated_configuration_models_the_simulators_odometry_noise(preset):
    # both localizers of a simulated compare assume the wheels' noise the simulator draws
    # (Thrun's alphas): a filter whose heading may wander faster than the robot's lets a moved
    # piece in view pull it along (docs/history.md, "The filter's odometry noise")
    from gatmo.pipeline.config import sim_stack_config

    amcl, odom = sim_stack_config().amcl, SimConfig.for_preset(preset).odom
    assert [amcl.alpha1, amcl.alpha2, amcl.alpha3, amcl.alpha4] == [
        odom.alpha1, odom.alpha2, odom.alpha3, odom.alpha4]


def test_a_run_trace_keeps_the_refusals_of_its_run():
    """run_side copies what GATMO refused this run (GatmoMapper.refusals, read after the
    run's end, which may still refuse) into the trace; a side without GATMO has none."""
    from types import SimpleNamespace

    from gatmo.pipeline.runs import run_side

    class Stack:
        n_map_updates = 0

        def __init__(self, mapper):
            self.mapper = mapper

        def begin_run(self, run_id):
            pass

        def end_run(self):
            if self.mapper is not None:  # a leaving track's last try
                self.mapper.refusals[(3, "beams")] = 1
            return []

    mapper = SimpleNamespace(refusals={(3, "score"): 2}, refused_at={(3, "score"): {(1.0, 2.0)}})
    t = run_side(Stack(mapper), [], log="l", side="gatmo", run_id=1)
    assert t.refusals == {(3, "score"): 2, (3, "beams"): 1}
    assert t.refused_at == {(3, "score"): {(1.0, 2.0)}}
    mapper.refusals.clear()
    assert t.refusals == {(3, "score"): 2, (3, "beams"): 1}  # a copy: the next run resets it
    assert run_side(Stack(None), [], log="l", side="static", run_id=1).refusals == {}


@pytest.mark.parametrize("keep", ["last", "first"])
def test_a_second_pass_localizes_on_the_map_the_first_ended_with(scen, keep, monkeypatch):
    from gatmo.pipeline import runs
    from gatmo.pipeline.config import sim_stack_config

    cfg = sim_stack_config()
    base = load_map(scen.map_yaml)
    scans = runs.load_scans(scen.logs[0])
    pose0 = scans[0].gt_pose_xytheta
    gt = np.array([s.gt_pose_xytheta for s in scans])
    one = runs._make_mapper(cfg, base, None)  # the same run in one pass
    single = runs.run_full(cfg, one, scans, 0, pose0, log="a", run_id=1)

    made = []
    real = runs.make_full_stack

    def spy(*a, **kw):
        made.append(real(*a, **kw))
        return made[-1]

    monkeypatch.setattr(runs, "make_full_stack", spy)
    cfg.fusion.passes, cfg.fusion.passes_objects = 2, keep
    mapper = runs._make_mapper(cfg, base, None)
    start = mapper.grid()
    trace = runs.run_full(cfg, mapper, scans, 0, pose0, log="a", run_id=1)
    first, second = made
    # the first pass is the one-pass run: on the start map, updated as GATMO changes it
    assert first.loc_grid is None and first.n_map_updates > 0
    assert first.mapper.grid() == one.grid() and not first.mapper.grid() == start
    # the second localizes on the map the first ended with, fixed, its GATMO starting again
    assert second.loc_grid == one.grid() and second.n_map_updates == 0
    assert second.mapper is not first.mapper
    kept = first.mapper if keep == "first" else second.mapper
    assert kept is mapper
    # the object map kept is that pass's, and so are the events; the poses are the second's
    if keep == "first":
        assert mapper.grid() == one.grid()
        assert [e["kind"] for e in trace.events] == [e["kind"] for e in single.events]
        np.testing.assert_array_equal(trace.gatmo_poses_xytheta, single.gatmo_poses_xytheta)
    else:
        assert not mapper.grid() == start and trace.events
    assert not np.array_equal(trace.poses_xytheta, single.poses_xytheta)
    err = np.hypot(*(trace.poses_xytheta[:, :2] - gt[:, :2]).T)
    assert np.median(err) < 0.1


def test_the_static_side_can_run_its_own_amcl_parameters(scen, tmp_path):
    """``--static-params``: the static side runs that AMCL YAML, exactly as ``--params`` would
    run it, and the full stack runs what it runs without it."""
    from gatmo.config import load_model
    from gatmo.localization.config import AmclConfig

    params = tmp_path / "amcl.yaml"  # ROS 1 names; a flat field, unlike the stack's default
    params.write_text("laser_model_type: likelihood_field\nlaser_sigma_hit: 0.3\n"
                      "laser_max_beams: 30\n")
    logs = [str(scen.logs[0])]
    common = ["--map", str(scen.map_yaml), "--max-scans", "60"]

    def poses(out, side):
        return np.loadtxt(out / side / "01_run_1" / "poses.tum")

    outs = {k: tmp_path / k for k in ("plain", "static_only", "both")}
    assert main(["compare", *logs, *common, "--out", str(outs["plain"])]) == 0
    assert main(["compare", *logs, *common, "--static-params", str(params),
                 "--out", str(outs["static_only"])]) == 0
    assert main(["compare", *logs, *common, "--params", str(params),
                 "--out", str(outs["both"])]) == 0
    mine = outs["static_only"]
    np.testing.assert_array_equal(poses(mine, "static"), poses(outs["both"], "static"))
    np.testing.assert_array_equal(poses(mine, "gatmo"), poses(outs["plain"], "gatmo"))
    assert not np.array_equal(poses(mine, "static"), poses(outs["plain"], "static"))
    saved = load_model(AmclConfig, mine / "static_amcl.yaml")
    assert (saved.laser_model, saved.sigma_hit_m, saved.max_beams) == ("likelihood_field", 0.3, 30)
    assert json.loads((mine / "summary.json").read_text())["static_config"] == "static_amcl.yaml"
    assert json.loads((outs["plain"] / "summary.json").read_text())["static_config"] == \
        "config.yaml"
    assert not (outs["plain"] / "static_amcl.yaml").exists()


def test_initial_pose_order():
    """``--initial-pose``, then ``--global``, then the configuration's (a ROS AMCL file's
    initial_pose_*), then the log's first ground-truth pose."""
    from types import SimpleNamespace

    from gatmo.pipeline.runs import initial_pose_for

    with_gt = [SimpleNamespace(gt_pose_xytheta=np.array([1.0, 2.0, 0.3]))]
    no_gt = [SimpleNamespace(gt_pose_xytheta=None)]
    given, configured = (5.0, 6.0, 0.1), (7.0, 8.0, -0.2)
    np.testing.assert_array_equal(initial_pose_for(with_gt, given, True, configured), given)
    assert initial_pose_for(with_gt, None, True, configured) is None
    np.testing.assert_array_equal(initial_pose_for(with_gt, None, False, configured), configured)
    np.testing.assert_array_equal(initial_pose_for(with_gt, None, False), [1.0, 2.0, 0.3])
    assert initial_pose_for(no_gt, None, False) is None


def test_run_and_compare_start_from_the_amcl_files_initial_pose(scen, tmp_path):
    """A ROS AMCL file's initial_pose_x / _y / _a is where ``gatmo run`` and ``gatmo compare``
    start, as AMCL does (they used to start from the log's ground truth, or globally)."""
    from gatmo.datasets.carmen import CarmenLog

    truth = next(iter(CarmenLog(scen.logs[0]))).gt_pose_xytheta
    start = truth + np.array([0.0, 0.5, 0.0])  # 0.5 m off, ten of the cloud's deviations
    params = tmp_path / "amcl.yaml"
    params.write_text(f"initial_pose_x: {start[0]}\ninitial_pose_y: {start[1]}\n"
                      f"initial_pose_a: {start[2]}\ninitial_cov_xx: 0.0025\n"
                      "initial_cov_yy: 0.0025\n")
    common = ["--map", str(scen.map_yaml), "--max-scans", "2"]
    assert main(["run", "--log", str(scen.logs[0]), *common, "--params", str(params),
                 "--out", str(tmp_path / "r")]) == 0
    assert main(["compare", str(scen.logs[0]), *common, "--params", str(params),
                 "--out", str(tmp_path / "c")]) == 0
    firsts = [np.loadtxt(tmp_path / "r" / "poses.tum")[0, 1:3],
              *(np.loadtxt(tmp_path / "c" / side / "01_run_1" / "poses.tum")[0, 1:3]
                for side in ("static", "gatmo"))]
    for xy in firsts:
        assert np.hypot(*(xy - start[:2])) < 0.2 < np.hypot(*(xy - truth[:2]))


@pytest.mark.skipif(not (DATA / "uob-meeting" / "simpath2.bag").exists(),
                    reason="../shared/data/uob-meeting (the Stage run) not found")
def test_real_stage_meeting_room_full_stack_not_worse_than_the_static_localizer(tmp_path):
    # The map in Stage's frame (map = 0.96462 x stage + (15.08, 15.26), ../shared/data/README):
    # resolution and origin rescaled, so the bag's own ground truth scores both sides. Nothing
    # moved in this room: the full stack on the real preset must not be worse (README, "Real
    # logs": 0.0715 static, 0.0719 full stack)
    import shutil

    s, t = 0.96462, np.array([15.08, 15.26])
    shutil.copy(DATA / "uob-meeting" / "meeting.pgm", tmp_path / "meeting.pgm")
    (tmp_path / "stage.yaml").write_text(
        f"image: meeting.pgm\nresolution: {0.05 / s:.10f}\norigin: [{-t[0] / s:.10f}, "
        f"{-t[1] / s:.10f}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    from gatmo.pipeline.runs import compare

    res = compare(tmp_path / "stage.yaml", [DATA / "uob-meeting" / "simpath2.bag"],
                  tmp_path / "c", preset="real", pictures=False)
    assert res.warnings == []
    static, full = (next(r for r in res.rows if r["side"] == side) for side in ("static", "gatmo"))
    assert static["ate_rmse_m"] < 0.1 and full["ate_rmse_m"] <= 1.05 * static["ate_rmse_m"]
    assert full["gatmo_trusted_fraction"] > 0.3  # GATMO had the scans, and changed nothing
    assert full["absent"] == full["relocated"] == full["added"] == 0
