"""``gatmo calibrate``: AMCL's odometry alphas fitted to a log, written as AMCL YAML."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gatmo.cli import main
from gatmo.datasets.carmen import CarmenLog, write_carmen
from gatmo.datasets.tum import write_tum
from gatmo.errors import ConfigError
from gatmo.localization.calibration import update_steps
from gatmo.localization.params import amcl_yaml_text, load_amcl_yaml
from gatmo.pipeline.calibrate import calibrate_odometry, reference_at

from ..helpers import make_scan, room_grid
from ..localization.test_calibration import truth_from_model, wander

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
ALPHAS = (0.05, 0.01, 0.08, 0.03, 0.0)


def write_log(path: Path, *, with_truth: bool = True, seed: int = 1) -> tuple[np.ndarray, ...]:
    """A CARMEN log whose odometry is at AMCL's update steps (0.25 m / 0.2 rad) and whose true
    poses (TRUEPOS) were drawn from the diff-corrected model with ALPHAS: returns (stamps, odom,
    truth)."""
    dense = wander(30000, seed=seed)
    odom = dense[update_steps(dense, 0.25, 0.2)]
    truth = truth_from_model(odom, "diff-corrected", ALPHAS, seed=seed + 1)
    world = room_grid(6.0, 6.0)
    stamps = np.arange(len(odom)) * 0.5
    scans = [make_scan(world, (3.0, 3.0, 0.0), n_beams=5, odom_pose_xytheta=o, stamp_s=t)
             for o, t in zip(odom, stamps, strict=True)]
    for s, g in zip(scans, truth, strict=True):
        s.gt_pose_xytheta = g if with_truth else None
    write_carmen(path, scans)
    return stamps, odom, truth


def test_calibrate_recovers_the_alphas_of_a_log_and_writes_amcl_yaml_that_loads(tmp_path, capsys):
    log = tmp_path / "run.log"
    write_log(log)
    out = tmp_path / "fitted.yaml"
    assert main(["calibrate", str(log), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "alpha1" in text and "held out" in text
    cfg = load_amcl_yaml(out)  # Nav2's layout: the file drops into a Nav2 params file
    assert "ros__parameters" in out.read_text()
    assert cfg.odom_model == "diff-corrected"
    assert (cfg.update_min_d_m, cfg.update_min_a_rad) == (0.25, 0.2)
    for got, want in zip((cfg.alpha1, cfg.alpha2, cfg.alpha3, cfg.alpha4), ALPHAS, strict=False):
        assert got == pytest.approx(want, rel=0.25)
    report = tmp_path / "fit.json"
    res = calibrate_odometry(log, report_path=report)
    assert json.loads(report.read_text())["alphas"] == res["alphas"]
    assert main(["info", str(report)]) == 0
    assert "odometry calibration" in capsys.readouterr().out
    np.testing.assert_allclose(res["z_std_holdout"], 1.0, atol=0.15)  # fits what it never saw
    # AMCL's defaults (0.2) predict errors far larger than these wheels make
    assert max(res["z_std_current"]) < 0.8
    assert res["warnings"] == []


def test_calibrate_against_a_tum_reference_with_a_clock_offset(tmp_path):
    log = tmp_path / "run.log"
    stamps, _, truth = write_log(log, with_truth=False, seed=3)
    write_tum(tmp_path / "ref.tum", stamps - 1000.0, truth)  # a clock 1000 s behind the log's
    a = calibrate_odometry(log, reference_path=tmp_path / "ref.tum", stamp_offset_s=1000.0)
    assert a["reference_coverage"] == 1.0
    for got, want in zip(a["alphas"], ALPHAS, strict=False):
        assert got == pytest.approx(want, rel=0.25)


def test_calibrate_keeps_a_ros1_file_s_dialect_and_model(tmp_path):
    log = tmp_path / "run.log"
    write_log(log, seed=5)
    params = tmp_path / "amcl.yaml"
    params.write_text("odom_model_type: diff\nupdate_min_d: 0.25\nupdate_min_a: 0.2\n")
    out = tmp_path / "fitted.yaml"
    res = calibrate_odometry(log, params_path=params, out_path=out)
    assert res["model"] == "diff"
    assert "odom_alpha1" in out.read_text() and "ros__parameters" not in out.read_text()
    cfg = load_amcl_yaml(out)
    assert cfg.odom_model == "diff" and cfg.alpha1 == pytest.approx(res["alphas"][0])


def test_calibrate_without_a_reference_says_how_to_make_one(tmp_path, capsys):
    log = tmp_path / "run.log"
    write_log(log, with_truth=False)
    assert main(["calibrate", str(log)]) == 1
    err = capsys.readouterr().err
    assert "--reference" in err and "map build" in err


def test_a_reference_covering_too_little_is_refused(tmp_path, capsys):
    log = tmp_path / "run.log"
    stamps, _, truth = write_log(log, with_truth=False)
    write_tum(tmp_path / "ref.tum", stamps[:5], truth[:5])
    assert main(["calibrate", str(log), "--reference", str(tmp_path / "ref.tum")]) == 1
    assert "ref.tum" in capsys.readouterr().err


def test_reference_counts_at_its_own_stamps_or_where_it_is_dense():
    t_ref = np.array([0.0, 0.5, 1.0, 5.0, 9.0])
    p_ref = np.c_[t_ref, np.zeros(5), np.zeros(5)]
    q = np.array([0.25, 3.0, 5.01, 7.0, 9.0, 10.0])
    valid, p = reference_at(q, t_ref, p_ref)
    np.testing.assert_array_equal(valid, [True, False, True, False, True, False])
    np.testing.assert_allclose(p[valid, 0], [0.25, 5.01, 9.0])


def test_nav2_has_no_ros1_variance_as_std_model():
    with pytest.raises(ConfigError, match="ROS 1 only"):
        amcl_yaml_text({"odom_model": "diff"}, "nav2")


@pytest.mark.skipif(not (DATA / "radish-corrected" / "intel-corrected.log.gz").exists(),
                    reason="../shared/data (Intel bag and radish's corrected log) not found")
def test_real_intel_odometry_against_radish_s_corrected_poses(tmp_path):
    # radish's gmapping poses are keyframes (a pose every 1 m or so, 976052857.33753 s behind
    # the bag's clock): the fit is at their spacing and says so
    scans = list(CarmenLog(DATA / "radish-corrected" / "intel-corrected.log.gz",
                           pose_is_reference=True, skip_bad=True))
    write_tum(tmp_path / "ref.tum", np.array([s.stamp_s for s in scans]),
              np.array([s.gt_pose_xytheta for s in scans]))
    res = calibrate_odometry(DATA / "slam-benchmark" / "intel.sort.bag",
                             reference_path=tmp_path / "ref.tum", stamp_offset_s=976052857.33753)
    assert res["steps"] > 800
    assert res["trans_scale"] == pytest.approx(1.0, abs=0.02)  # the wheels' scale is right
    assert all(0.7 < z < 1.5 for z in res["z_std_holdout"])
    assert any("sparser than the filter's updates" in w for w in res["warnings"])


@settings(max_examples=60, deadline=None)
@given(dialect=st.sampled_from(["nav2", "ros1"]),
       model=st.sampled_from(["diff-corrected", "omni-corrected", "diff", "omni"]),
       alphas=st.lists(st.floats(0.0, 50.0, allow_nan=False), min_size=5, max_size=5),
       d=st.floats(0.0, 2.0, allow_nan=False), a=st.floats(0.0, 3.0, allow_nan=False))
def test_written_amcl_yaml_reads_back_to_the_same_values(tmp_path_factory, dialect, model,
                                                         alphas, d, a):
    values = {"odom_model": model, "update_min_d_m": d, "update_min_a_rad": a}
    values.update({f"alpha{i + 1}": v for i, v in enumerate(alphas)})
    if dialect == "nav2" and not model.endswith("-corrected"):
        with pytest.raises(ConfigError):
            amcl_yaml_text(values, dialect)
        return
    path = tmp_path_factory.mktemp("y") / "amcl.yaml"
    path.write_text(amcl_yaml_text(values, dialect))
    cfg = load_amcl_yaml(path)
    assert {k: getattr(cfg, k) for k in values} == values


@pytest.mark.skipif(not (DATA / "slam-benchmark" / "mit-csail.sort.bag").exists(),
                    reason="../shared/data (the MIT CSAIL bag) not found")
def test_real_mit_csail_odometry_against_its_own_pose_graph(tmp_path):
    # the flow a user without ground truth has: map build's poses as the reference
    from gatmo.pipeline.mapping import build_map

    bag = DATA / "slam-benchmark" / "mit-csail.sort.bag"
    build_map(bag, tmp_path / "m.yaml", poses_out=tmp_path / "p.tum", max_scans=600)
    res = calibrate_odometry(bag, reference_path=tmp_path / "p.tum", preset="real",
                             max_scans=600)
    assert res["reference_coverage"] == 1.0 and res["warnings"] == []
    assert res["steps"] > 400
    # AMCL's 0.2 make the filter expect three times the translation error these wheels make
    assert res["z_std_current"][1] < 0.5
    np.testing.assert_allclose(res["z_std_fitted"], 1.0, atol=0.1)
    assert max(res["z_std_holdout"]) < 1.3
    assert res["trans_scale"] == pytest.approx(1.0, abs=0.03)
    # the pose graph's jitter, along the corridors (ICP's weak direction): under 2 cm
    assert 0.0 < res["reference_noise_std"][0] < 0.02


@pytest.mark.skipif(not (DATA / "uob-meeting" / "simpath2.bag").exists(),
                    reason="../shared/data (the UoB Stage bag) not found")
def test_real_noise_free_stage_odometry_is_said_to_have_no_noise_and_floored(tmp_path, capsys):
    # Stage's odometry is noise-free (the data's README): its ground truth, in Stage's frame,
    # is a fine reference (only relative motions count), and some alphas come out at 0
    bag = DATA / "uob-meeting" / "simpath2.bag"
    out = tmp_path / "fitted.yaml"
    assert main(["calibrate", str(bag), "--out", str(out), "--min-alpha", "0.005"]) == 0
    assert "fitted to about 0" in capsys.readouterr().out
    cfg = load_amcl_yaml(out)
    alphas = (cfg.alpha1, cfg.alpha2, cfg.alpha3, cfg.alpha4)
    assert min(alphas) == 0.005 and max(alphas) < 0.05  # AMCL's 0.2 are far too much here
    res = calibrate_odometry(bag)
    assert max(res["z_std_current"]) < 0.3


def test_calibrate_pools_several_logs_without_a_step_across_them(tmp_path, capsys):
    a, b = tmp_path / "a.log", tmp_path / "b.log"
    write_log(a, seed=7)
    write_log(b, seed=9)
    one = calibrate_odometry(a)
    both = calibrate_odometry([a, b])
    # every step is within one log: the pooled steps are the two logs' own
    two = calibrate_odometry(b)
    assert both["steps"] + both["rejected"] == (one["steps"] + one["rejected"]
                                                + two["steps"] + two["rejected"])
    for got, want in zip(both["alphas"], ALPHAS, strict=False):
        assert got == pytest.approx(want, rel=0.2)
    assert main(["calibrate", str(a), str(b), "--reference", str(tmp_path / "x.tum")]) == 1
    assert "one --reference per log" in capsys.readouterr().err


def test_a_simulated_run_calibrates_the_same_from_its_carmen_log_and_its_ros2_bag(tmp_path):
    # the same odometry and ground truth through both readers (the bag's /odom interpolated
    # at the scans' stamps); and the simulator's per-scan noise is not the filter's per update
    from gatmo.pipeline.runs import simulate

    simulate(tmp_path, runs=1, seed=5, bag=True)
    stack = tmp_path / "stack.yaml"
    clf = calibrate_odometry(tmp_path / "run_1.clf", config_path=stack)
    bag = calibrate_odometry(tmp_path / "run_1_bag", config_path=stack)
    assert clf["steps"] == bag["steps"]
    np.testing.assert_allclose(clf["alphas"], bag["alphas"], rtol=1e-3, atol=1e-6)
    assert clf["current_alphas"] == [0.05, 0.01, 0.05, 0.01]
    assert max(clf["z_std_current"]) < 0.8  # per update, those predict too much noise
