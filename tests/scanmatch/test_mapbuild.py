"""Loop closure and map building: the correlative kernels agree with numpy, a closure is found
from a poor guess and refused in a corridor, a drifted synthetic loop is closed, a real log
(MIT CSAIL, first scans) gets a map and a trajectory better than ICP odometry, itself
better than the wheels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gatmo.geometry import compose, relative
from gatmo.scanmatch.correlative import (
    block_scores_reference,
    correlative_scores_reference,
    likelihood_field,
    match_to_submap,
)
from gatmo.scanmatch.icp import voxel_downsample
from tests.helpers import make_scan, room_grid

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "slam-benchmark"
BOXES = [(2, 2, 3, 2.6), (6, 5, 6.4, 6.5), (7, 1, 8.5, 1.3), (3.5, 6, 4.5, 6.8), (9, 4, 9.5, 5)]


def _pts(grid, pose, **kw):
    s = make_scan(grid, pose, n_beams=181, max_range_m=kw.pop("max_range_m", 8.0), **kw)
    return voxel_downsample(s.points_base_xy(), 0.05)


def test_correlative_kernels_agree_with_numpy():
    from gatmo.scanmatch._kernels import block_scores_kernel, correlative_scores_kernel

    rng = np.random.default_rng(1)
    field = rng.random((40, 50))
    cx = rng.integers(-5, 55, (3, 20))
    cy = rng.integers(-5, 45, (3, 20))
    offs = np.arange(-4, 5, 2)
    a = correlative_scores_kernel(field, cx, cy, offs, offs)
    b = correlative_scores_reference(field, cx, cy, offs, offs)
    assert np.allclose(a, b) and a.shape == (3, 5, 5)
    ba, bx, by = np.array([0, 2, 1]), np.array([-4, 0, 3]), np.array([2, -4, 3])
    a = block_scores_kernel(field, cx, cy, ba, bx, by, 3, 4)
    b = block_scores_reference(field, cx, cy, ba, bx, by, 3, 4)
    assert np.allclose(a, b) and (a[2] == -1).sum() == 5  # offsets beyond +-4 masked


def test_closure_found_from_a_poor_guess_and_refused_in_a_corridor():
    g = room_grid(11, 8, 0.05, boxes=BOXES)
    a = np.array([4.0, 4.0, 0.3])
    T = np.array([0.8, -0.6, np.radians(20)])
    target = _pts(g, a)
    source = _pts(g, compose(a, T))
    guess = T + np.array([1.2, 0.9, np.radians(-12)])  # ICP alone starts 1.5 m, 12 deg off
    m = match_to_submap(source, target, guess, window_xy_m=2.0, window_theta_rad=0.3)
    err = relative(T, m.T_target_source)
    assert m.accepted, m.reason
    assert np.hypot(err[0], err[1]) < 0.03 and abs(np.degrees(err[2])) < 0.5
    # a featureless corridor: every shift along it fits, so no closure may be accepted
    c = room_grid(40, 2.4, 0.05)
    p = np.array([20.0, 1.2, 0.0])
    tgt = _pts(c, p, max_range_m=6.0)
    src = _pts(c, compose(p, [0.5, 0.0, 0.0]), max_range_m=6.0)
    m = match_to_submap(src, tgt, [1.5, 0.0, 0.0], window_xy_m=2.0, window_theta_rad=0.2)
    assert not m.accepted and m.reason in ("ambiguous", "degenerate")


def test_likelihood_field_peaks_on_points():
    f = likelihood_field(np.array([[0.0, 0.0], [1.0, 0.0]]), resolution_m=0.05, sigma_m=0.1)
    c = np.floor((np.array([0.0, 0.0]) - f.origin_xy) / 0.05).astype(int)
    assert f.values[c[1], c[0]] == pytest.approx(1.0)
    assert f.values[c[1] + 10, c[0]] < 0.01  # 0.5 m away


def _square_loop(laps=2, side_m=6.0, step_m=0.4):
    out = []
    corners = [(2.5, 1.0), (2.5 + side_m, 1.0), (2.5 + side_m, 7.0 - 1.0), (2.5, 6.0)]
    for _ in range(laps):
        for i in range(4):
            (x0, y0), (x1, y1) = corners[i], corners[(i + 1) % 4]
            n = int(round(np.hypot(x1 - x0, y1 - y0) / step_m))
            th = np.arctan2(y1 - y0, x1 - x0)
            out += [[x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n, th] for k in range(n)]
    return np.array(out)


def test_pose_graph_closes_a_drifted_synthetic_loop():
    from gatmo.scanmatch.posegraph import GraphConfig, optimize

    g = room_grid(11, 8, 0.05, boxes=[(4.5, 3, 5.5, 3.6), (7, 3.2, 7.4, 4.5), (0.6, 3, 1.2, 5),
                                      (9.8, 6, 10.4, 7.2), (5, 7.0, 6, 7.4)])
    truth = _square_loop()
    rng = np.random.default_rng(2)
    odo = [truth[0]]
    for i in range(1, len(truth)):  # 0.4 deg per step heading drift + 3 % scale
        step = relative(truth[i - 1], truth[i]) * [1.03, 1.03, 1.0] + [0, 0, np.radians(0.4)]
        odo.append(compose(odo[-1], step))
    odo = np.array(odo)
    pts = [_pts(g, p, noise_m=0.01, rng=rng) for p in truth]
    cfg = GraphConfig(closure_min_separation=15, submap_half_width=3)
    res = optimize(odo, pts, cfg)

    def end_error(p):  # end pose relative to the start vs the truth's
        e = relative(relative(p[0], p[-1]), relative(truth[0], truth[-1]))
        return np.hypot(e[0], e[1])

    assert len(res.closures) >= 3
    assert end_error(odo) > 1.0
    assert end_error(res.poses_xytheta) < 0.1

    def max_error(est):
        e = np.array([relative(relative(est[0], p), relative(truth[0], q))
                      for p, q in zip(est, truth, strict=True)])
        return np.hypot(e[:, 0], e[:, 1]).max()

    print(max_error(odo), max_error(res.poses_xytheta), res.stats["accepted"])
    assert max_error(res.poses_xytheta) < 0.25 * max_error(odo)


def test_map_build_on_the_first_mit_csail_scans(tmp_path):
    bag = DATA / "mit-csail.sort.bag"
    if not bag.exists():
        pytest.skip(f"{bag} not found: real data absent")
    from gatmo.datasets.metrics import relations_error
    from gatmo.datasets.relations import read_relations
    from gatmo.datasets.rosbag import RosBag
    from gatmo.maps.io import load_map
    from gatmo.pipeline.mapping import build_map, build_trajectory

    scans = list(RosBag(bag))[:600]
    icp, opt, res, _ = build_trajectory(scans)
    rel = read_relations(DATA / "mit-csail.relations")
    t = np.array([s.stamp_s for s in scans])
    e_icp = relations_error(t, icp, rel)
    e_opt = relations_error(t, opt, rel)
    assert e_opt["n_used"] > 200
    assert len(res.closures) > 0
    odo = np.array([s.odom_pose_xytheta for s in scans])
    e_odo = relations_error(t, odo, rel)
    # measured: wheels 0.040 m / 3.2 deg, ICP odometry 0.029 m / 0.59 deg, graph 0.025 m /
    # 0.54 deg (ICP was 0.078 m / 1.7 deg before it handled odometry stalls and spikes)
    assert e_icp["trans_mean_m"] < 0.85 * e_odo["trans_mean_m"]
    assert e_icp["rot_mean_deg"] < 0.3 * e_odo["rot_mean_deg"]
    assert e_opt["trans_mean_m"] < 0.95 * e_icp["trans_mean_m"]
    assert e_opt["trans_mean_m"] < 0.03 and e_opt["rot_mean_deg"] < 0.8
    # the command's library call writes a loadable map and the trajectory
    summary = build_map(bag, tmp_path / "m.yaml", poses_out=tmp_path / "p.tum", max_scans=150)
    grid = load_map(tmp_path / "m.yaml")
    assert summary.scans == 150 and grid.occupied.sum() > 500
    assert len((tmp_path / "p.tum").read_text().splitlines()) == 151


def test_scans_with_too_few_points_fall_back_to_odometry_and_are_counted():
    from gatmo.pipeline.mapping import build_trajectory

    g = room_grid(11, 8, 0.05, boxes=BOXES)
    truth = np.array([[2.0 + 0.1 * i, 4.0, 0.0] for i in range(40)])
    scans = []
    for i, p in enumerate(truth):
        s = make_scan(g, p, n_beams=181, max_range_m=8.0, odom_pose_xytheta=p,
                      stamp_s=0.1 * i)
        if i % 5 == 3:  # blinded: every return beyond range, no valid point
            s.ranges_m[:] = np.inf
        scans.append(s)
    icp, opt, res, stats = build_trajectory(scans)
    assert stats["fallback_few_points"] == 8
    assert len(opt) == 40 and np.isfinite(opt).all()
    err = np.hypot(*(opt[:, :2] - (truth[:, :2] - truth[0, :2])).T)
    assert err.max() < 0.05  # odometry (exact here) carried the blinded scans


@pytest.fixture(scope="module")
def office_log(tmp_path_factory):
    """A 20 s simulated office run as a CARMEN log, and its scans (with the truth)."""
    from gatmo.datasets.carmen import write_carmen
    from gatmo.datasets.sim import SimConfig, make_world, simulate_run

    rng = np.random.default_rng(7)
    cfg = SimConfig.for_preset("office")
    cfg.robot.duration_s = 20
    world, route = make_world("office", rng)
    scans = simulate_run(world, route, cfg, rng)
    return write_carmen(tmp_path_factory.mktemp("office") / "run.clf", scans), scans


def test_map_build_command_on_a_simulated_carmen_log(tmp_path, office_log):
    from gatmo.cli import main
    from gatmo.datasets.tum import read_tum
    from gatmo.maps.io import load_map

    log, scans = office_log
    rc = main(["map", "build", str(log), "--out", str(tmp_path / "m.yaml"), "--poses-out",
               str(tmp_path / "p.tum"), "--odometry-out", str(tmp_path / "o.tum"),
               "--resolution", "0.1"])
    assert rc == 0
    grid = load_map(tmp_path / "m.yaml")
    assert grid.resolution_m == pytest.approx(0.1) and grid.occupied.sum() > 100
    gt = np.array([s.gt_pose_xytheta for s in scans])
    ref = np.array([relative(gt[0], q) for q in gt])
    # both trajectories (first scan's frame) match the truth's shape
    for name in ("p.tum", "o.tum"):
        t, poses = read_tum(tmp_path / name)
        assert len(poses) == len(scans)
        assert np.hypot(*(poses[:, :2] - ref[:, :2]).T).max() < 0.3


def test_a_map_is_built_again_to_the_byte_from_the_configuration_saved_beside_it(
        tmp_path, office_log, capsys):
    """``MAP.build.yaml`` holds every parameter the map was built with, flags included: a
    second build from it alone gives the same image."""
    from gatmo.cli import main
    from gatmo.pipeline.config import MapBuildConfig, load_map_build_config

    log, _ = office_log
    first = tmp_path / "a" / "m.yaml"
    first.parent.mkdir()
    tuned = tmp_path / "tuned.yaml"
    assert main(["config", "dump", "mapping"]) == 0
    text = capsys.readouterr().out.replace("keyframe_dist_m: 0.5", "keyframe_dist_m: 0.8")
    tuned.write_text(text)
    assert main(["map", "build", str(log), "--out", str(first), "--config", str(tuned),
                 "--max-range", "6"]) == 0
    saved = load_map_build_config(tmp_path / "a" / "m.build.yaml")
    expect = MapBuildConfig()
    expect.graph.keyframe_dist_m = 0.8
    expect.render.max_range_m = 6.0
    assert saved == expect
    second = tmp_path / "b" / "m.yaml"
    second.parent.mkdir()
    assert main(["map", "build", str(log), "--out", str(second), "--config",
                 str(tmp_path / "a" / "m.build.yaml")]) == 0
    assert (tmp_path / "b" / "m.pgm").read_bytes() == (tmp_path / "a" / "m.pgm").read_bytes()
    # and `gatmo info` tells the file for what it is
    from gatmo.datasets.info import summarize

    info = summarize(tmp_path / "a" / "m.build.yaml")
    assert info["kind"] == "map build config" and info["parameters_not_defaults"] == 2


def test_the_map_build_configuration_changes_what_is_built(tmp_path, office_log):
    from gatmo.maps.io import load_map
    from gatmo.pipeline.config import MapBuildConfig
    from gatmo.pipeline.mapping import build_map

    log, _ = office_log
    base = build_map(log, tmp_path / "base.yaml")
    cfg = MapBuildConfig()
    cfg.graph.keyframe_dist_m = 1.5  # fewer graph nodes
    cfg.render.occupied_thresh = 0.9  # a cell needs about three hits, not one
    cfg.render.resolution_m = 0.1
    tuned = build_map(log, tmp_path / "tuned.yaml", cfg=cfg)
    assert tuned.keyframes < 0.7 * base.keyframes
    a, b = load_map(tmp_path / "base.yaml"), load_map(tmp_path / "tuned.yaml")
    assert b.resolution_m == pytest.approx(0.1)
    # occupied area [m^2]: fewer cells pass the higher threshold, though each is 4x larger
    assert b.occupied.sum() * 0.01 < 0.9 * a.occupied.sum() * 0.0025 * 4
    assert cfg == MapBuildConfig.model_validate(cfg.model_dump())  # the caller's is untouched
    assert build_map(log, tmp_path / "x.yaml", cfg=cfg, resolution_m=0.2).resolution_m == 0.2
    assert cfg.render.resolution_m == 0.1


def test_map_build_on_a_laser_only_bag_and_with_the_wheels_ignored(tmp_path, office_log,
                                                                     capsys):
    """A bag of scans alone (what a KISS-ICP user records) builds a map from constant
    velocity; ``--no-odometry`` does so on a log that has wheels, and is saved with the map."""
    from gatmo.cli import main
    from gatmo.datasets.rosbag import write_ros2_bag
    from gatmo.datasets.tum import read_tum
    from gatmo.maps.io import load_map
    from gatmo.pipeline.config import load_map_build_config

    log, scans = office_log
    bag = write_ros2_bag(tmp_path / "laser_only", scans, odom_topic=None)
    gt = np.array([s.gt_pose_xytheta for s in scans])
    ref = np.array([relative(gt[0], q) for q in gt])
    # the wheels of the simulated office drift: scans alone must do at least as well
    odo = np.array([s.odom_pose_xytheta for s in scans])
    odo = np.array([relative(odo[0], q) for q in odo])
    wheels_m = np.hypot(*(odo[:, :2] - ref[:, :2]).T).max()
    for src, extra, out, says in ((bag, [], "a", "none in the log"),
                                  (log, ["--no-odometry"], "b", "icp.use_odometry false")):
        d = tmp_path / out
        d.mkdir()
        assert main(["map", "build", str(src), "--out", str(d / "m.yaml"), "--poses-out",
                     str(d / "p.tum"), *extra]) == 0
        assert says in capsys.readouterr().out
        assert load_map(d / "m.yaml").occupied.sum() > 100
        _, poses = read_tum(d / "p.tum")
        err = np.hypot(*(poses[:, :2] - ref[:, :2]).T).max()
        assert err < 0.3 and err < wheels_m, (out, err, wheels_m)
    assert load_map_build_config(tmp_path / "b" / "m.build.yaml").icp.use_odometry is False
    assert load_map_build_config(tmp_path / "a" / "m.build.yaml").icp.use_odometry is True
    # every other command still needs the wheels, and says where a laser-only bag can go
    assert main(["localize", "--map", str(tmp_path / "a" / "m.yaml"), "--log", str(bag),
                 "--out", str(tmp_path / "loc.tum")]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]  # after the progress bar
    assert err.startswith(f"error: {bag}: no odometry") and "map build" in err


def test_a_bad_map_build_configuration_is_one_line_and_nothing_is_written(
        tmp_path, office_log, capsys):
    from gatmo.cli import main

    log, _ = office_log
    bad = tmp_path / "bad.yaml"
    for text, where in (("graph:\n  keyframe_dist_m: 0.5\n  closure_windw: 3\n",
                         ":3: graph.closure_windw: unknown key"),
                        ("render:\n  free_thresh: 0.7\n",
                         ":1: render: free_thresh (0.7) must be below occupied_thresh (0.65)"),
                        ("icp:\n  voxel_m: -1\n", ":2: icp.voxel_m: Input should be greater")):
        bad.write_text(text)
        assert main(["map", "build", str(log), "--out", str(tmp_path / "m.yaml"), "--config",
                     str(bad)]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"error: {bad}{where}"), err
        assert len(err.splitlines()) == 1
        assert not (tmp_path / "m.yaml").exists() and not (tmp_path / "m.build.yaml").exists()


@pytest.mark.slow
def test_icp_odometry_over_the_whole_mit_csail_log_survives_its_odometry_jumps():
    # MIT CSAIL's wheels stall and spike; ICP from such a guess can settle 9-20 deg off with a
    # passing fitness, and one such step spoils every long relation across it. At a jump ICP
    # starts from both guesses and the lower residual wins; where ICP from the odometry fails,
    # it starts from constant velocity. Without that retry the figure was a draw of rounding:
    # 0.15-0.62 m over kernel scales 1e-12 apart (and 0.26 or 0.52 m by which OpenBLAS kernel
    # numpy ran), from 0-6 scans of a stalled turn falling back to the wheels. With it, and
    # jumps at 0.2 m / 0.2 rad, one draw of three on another machine still came out 1.47 m: a
    # stall at the start of a turn (0.15 rad from constant velocity) was no jump, and ICP from
    # the stalled wheels fitted 0.28 m backwards. With jumps at 0.1 m / 0.1 rad: 0.13-0.17 m
    # over seven draws, none falling back (README, "Scan matching").
    bag = DATA / "mit-csail.sort.bag"
    if not bag.exists():
        pytest.skip(f"{bag} not found: real data absent")
    from gatmo.datasets.metrics import relations_error
    from gatmo.datasets.relations import read_relations
    from gatmo.datasets.rosbag import RosBag
    from gatmo.scanmatch import IcpConfig, ScanMatchOdometry

    scans = list(RosBag(bag))
    rel = read_relations(DATA / "mit-csail.relations")
    t = np.array([s.stamp_s for s in scans])
    for nudge in (0.0, 2e-12, 5e-12):  # three draws of the rounding
        odo = ScanMatchOdometry(IcpConfig(kernel_scale_m=0.05 * (1 + nudge)))
        poses = np.array([odo.register(s).pose_xytheta for s in scans])
        e = relations_error(t, poses, rel)
        assert e["n_used"] == 1172
        assert e["trans_mean_m"] < 0.3 and e["rot_mean_deg"] < 1.2, (nudge, e)
        assert odo.stats["odom_jumps"] > 100 and odo.stats["velocity_guess"] > 20
        assert odo.stats["fallback_bad_fit"] <= 1, (nudge, odo.stats)


def _whole_log(name):
    bag = DATA / f"{name}.sort.bag"
    if not bag.exists():
        pytest.skip(f"{bag} not found: real data absent")
    from gatmo.datasets.relations import read_relations
    from gatmo.datasets.rosbag import RosBag

    scans = list(RosBag(bag))
    return scans, np.array([s.stamp_s for s in scans]), read_relations(DATA / f"{name}.relations")


def _icp_relations_error(scans, t, rel, cfg):
    from gatmo.datasets.metrics import relations_error
    from gatmo.scanmatch import ScanMatchOdometry

    odo = ScanMatchOdometry(cfg)
    poses = np.array([odo.register(s).pose_xytheta for s in scans])
    return relations_error(t, poses, rel), odo.stats


@pytest.mark.slow
def test_scans_alone_match_the_mit_csail_and_aces_logs_better_than_kiss_icp():
    # KISS-ICP ignores wheels: on the same logs it gives 5.58 m (MIT CSAIL) and 3.13 m (ACES).
    # Ours from constant velocity alone, measured over five draws of the rounding: MIT CSAIL
    # 0.07-0.12 m (its wheels stall and spike: better than with them), ACES 0.25-0.31 m. ACES
    # holds a 3 s gap with an 84 deg turn in it, which the correlative rescue bridges: without
    # it ACES gave 1.15 m; without the extra headings, MIT CSAIL 5.9 m
    from gatmo.scanmatch import IcpConfig

    for name, bound_m, bound_deg in (("mit-csail", 0.25, 1.0), ("aces", 0.5, 1.5)):
        scans, t, rel = _whole_log(name)
        e, st = _icp_relations_error(scans, t, rel, IcpConfig(use_odometry=False))
        assert st["no_odometry"] == len(scans) - 1
        assert e["trans_mean_m"] < bound_m and e["rot_mean_deg"] < bound_deg, (name, e)
        if name == "aces":
            assert st["rescued"] >= 1


@pytest.mark.slow
def test_the_correlative_rescue_halves_the_intel_icp_odometry_error():
    # Intel's sorted bag pairs scans and wheels badly in places; where ICP fails from both
    # guesses the pose used to follow the wheels: 2.0-3.1 m over three draws. With the rescue
    # (about 30 of 13,631 scans placed by it) 0.56-1.33 m over its draws
    from gatmo.scanmatch import IcpConfig

    scans, t, rel = _whole_log("intel")
    e, st = _icp_relations_error(scans, t, rel, IcpConfig())
    assert 15 <= st["rescued"] <= 60 and st["rescued"] <= st["rescue_tried"]
    assert e["trans_mean_m"] < 1.6, e
