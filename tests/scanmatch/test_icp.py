"""ICP recovers known transforms; degenerate geometry is flagged; the odometry beats wheels."""

from __future__ import annotations

import numpy as np
import pytest

from gatmo.geometry import compose, relative, transform_points
from gatmo.scanmatch import IcpConfig, ScanMatchOdometry, icp_2d
from tests.helpers import make_scan, room_grid


def test_icp_recovers_known_transform():
    g = room_grid(10, 8, 0.05, boxes=[(2, 2, 3, 2.6), (6, 5, 6.4, 6.5), (7, 1, 8.5, 1.3)])
    a = np.array([4.0, 4.0, 0.2])
    T = np.array([0.3, -0.2, np.radians(8)])
    b = compose(a, T)
    sa = make_scan(g, a, n_beams=361, fov_rad=2 * np.pi * 0.99, max_range_m=12)
    sb = make_scan(g, b, n_beams=361, fov_rad=2 * np.pi * 0.99, max_range_m=12)
    res = icp_2d(sb.points_base_xy(), sa.points_base_xy(), (0, 0, 0), max_corr_dist_m=1.0,
                 max_iter=60)
    err = relative(T, res.T_target_source)
    assert np.hypot(err[0], err[1]) < 0.01 and abs(np.degrees(err[2])) < 0.2
    assert res.converged and not res.degenerate and res.fitness > 0.8


def test_geman_mcclure_ignores_furniture_that_moved_a_little():
    """The map has three boxes where the scan sees them 0.15 m further along x: Huber weights
    let those returns drag the alignment along x, Geman-McClure's redescending weights do not."""
    boxes = [(2, 2, 3, 2.6), (6, 5, 6.4, 6.5), (7, 1, 8.5, 1.3)]
    g_map = room_grid(10, 8, 0.05, boxes=boxes)
    g_now = room_grid(10, 8, 0.05, boxes=[(x0 + 0.15, y0, x1 + 0.15, y1)
                                          for x0, y0, x1, y1 in boxes])
    truth = np.array([4.0, 4.0, 0.2])
    target = transform_points(truth, make_scan(g_map, truth, n_beams=721,
                                               fov_rad=2 * np.pi * 0.99,
                                               max_range_m=12).points_base_xy())
    src = make_scan(g_now, truth, n_beams=361, fov_rad=2 * np.pi * 0.99,
                    max_range_m=12).points_base_xy()
    start = truth + np.array([0.04, -0.03, np.radians(1)])
    errs = {}
    for kernel in ("huber", "geman_mcclure"):
        res = icp_2d(src, target, start, max_corr_dist_m=0.3, max_iter=60, kernel=kernel)
        errs[kernel] = float(np.hypot(*(res.T_target_source[:2] - truth[:2])))
    assert errs["geman_mcclure"] < 0.005 < errs["huber"]


def test_corridor_is_degenerate_along_its_axis():
    g = room_grid(40, 2, 0.05)  # long corridor, walls far beyond the laser along x
    s = make_scan(g, (20, 1, 0), n_beams=181, max_range_m=5)
    res = icp_2d(s.points_base_xy(), s.points_base_xy(), (0.2, 0, 0))
    assert res.degenerate
    ev, vec = np.linalg.eigh(res.cov[:2, :2])
    assert abs(vec[0, -1]) > 0.9  # the most uncertain direction is x, the corridor's axis


def test_scan_matching_odometry_beats_wheel_odometry():
    from gatmo.datasets.sim import SimConfig, make_world, simulate_run

    rng = np.random.default_rng(5)
    cfg = SimConfig.for_preset("office")
    cfg.robot.duration_s = 30
    cfg.odom.scale_bias_std = 0.05
    world, route = make_world("office", rng)
    scans = simulate_run(world, route, cfg, rng)
    sm = ScanMatchOdometry.from_config(IcpConfig())
    poses = np.array([sm.register(s).pose_xytheta for s in scans])
    gt = np.array([s.gt_pose_xytheta for s in scans])
    od = np.array([s.odom_pose_xytheta for s in scans])

    def drift(p):
        est = np.array([relative(p[0], q) for q in p])
        ref = np.array([relative(gt[0], q) for q in gt])
        return np.hypot(*(est[:, :2] - ref[:, :2]).T)[-1]

    assert drift(poses) < 0.5 * drift(od)
    assert sm.stats["icp"] > 0.8 * len(scans)



@pytest.mark.parametrize("glitch", ["stall", "spike"])
def test_odometry_that_stalls_or_spikes_is_followed_by_constant_velocity(glitch):
    # MIT CSAIL's wheel odometry reports no motion for four scans, then all of it at once
    # (0.85 m / 50 deg in one step), and once turns 0.8 rad in a 0.35 rad/scan turn: ICP from
    # those guesses alone fails or locks onto a wrong fit
    from tests.helpers import drive_scans

    g = room_grid(11, 8, 0.05, boxes=[(2, 2, 3, 2.6), (6, 5, 6.4, 6.5), (7, 1, 8.5, 1.3),
                                      (3.5, 6, 4.5, 6.8), (9, 4, 9.5, 5)])
    truth = np.array([[2.0 + 0.15 * i, 3.0 + 0.05 * i, 0.12 * i] for i in range(30)])
    scans = drive_scans(g, truth, max_range_m=8.0)
    for i, s in enumerate(scans):
        s.stamp_s = 0.2 * i
    if glitch == "stall":  # odometry stays where it was at scan 11, then catches up at 16
        for i in range(12, 16):
            scans[i].odom_pose_xytheta = scans[11].odom_pose_xytheta.copy()
    else:  # scan 12's odometry step turns 0.5 rad more than the robot; the rest is right
        o11 = scans[11].odom_pose_xytheta.copy()
        for s in scans[12:]:
            s.odom_pose_xytheta = compose(o11, compose(np.array([0.0, 0.0, 0.5]),
                                                       relative(o11, s.odom_pose_xytheta)))

    def final_error(cfg):
        sm = ScanMatchOdometry.from_config(cfg)
        poses = np.array([sm.register(s).pose_xytheta for s in scans])
        e = relative(relative(poses[0], poses[-1]), relative(truth[0], truth[-1]))
        return np.hypot(e[0], e[1]), abs(e[2]), sm.stats

    xy, th, stats = final_error(IcpConfig())
    assert stats["velocity_guess"] >= 1 and stats["icp"] == len(scans) - 1
    assert xy < 0.03 and np.degrees(th) < 0.5
    # never treated as a jump (thresholds out of reach): ICP from the glitched odometry fails,
    # and constant velocity, tried where it fails, still recovers the step (the glitch stayed
    # in the trajectory, 1.4 m / 28 deg, before that retry: sixty-seventh session)
    xy_off, th_off, st = final_error(IcpConfig(odom_jump_m=100.0, odom_jump_rad=100.0))
    assert st["odom_jumps"] == 0 and st["velocity_guess"] >= 1
    assert st["fallback_bad_fit"] == 0 and st["icp"] == len(scans) - 1
    assert xy_off < 0.03 and np.degrees(th_off) < 0.5

def test_kiss_icp_backend_follows_a_simulated_run():
    from gatmo.datasets.sim import SimConfig, make_world, simulate_run
    from gatmo.scanmatch.kiss import KissIcpBackend

    rng = np.random.default_rng(6)
    cfg = SimConfig.for_preset("office")
    cfg.robot.duration_s = 15
    world, route = make_world("office", rng)
    scans = simulate_run(world, route, cfg, rng)
    k = KissIcpBackend(voxel_m=0.05, max_range_m=10.0)
    poses = np.array([k.register(s).pose_xytheta for s in scans])
    gt = np.array([s.gt_pose_xytheta for s in scans])
    est = relative(poses[0], poses[-1])
    ref = relative(gt[0], gt[-1])
    assert np.hypot(*ref[:2]) > 2.0
    assert np.hypot(*(est[:2] - ref[:2])) < 0.25 * np.hypot(*ref[:2])


def test_pose_graph_closes_a_loop_and_a_wrong_closure_is_down_weighted():
    from gatmo.scanmatch.posegraph import GraphConfig, optimize

    # a 4 m square driven twice, odometry with a heading drift of 0.5 deg per step
    truth = []
    for _lap in range(2):
        for side in range(4):
            for k in range(8):
                th = side * np.pi / 2
                start = [(0, 0), (4, 0), (4, 4), (0, 4)][side]
                truth.append([start[0] + 0.5 * k * np.cos(th), start[1] + 0.5 * k * np.sin(th),
                              th])
    truth = np.array(truth)
    odo = [truth[0]]
    for i in range(1, len(truth)):
        step = relative(truth[i - 1], truth[i]) + [0, 0, np.radians(0.5)]
        odo.append(compose(odo[-1], step))
    odo = np.array(odo)
    n = len(truth)
    good = [(i, i + 32, relative(truth[i], truth[i + 32])) for i in range(0, 32, 4)]
    wrong = [(5, 50, np.array([2.0, -1.5, 0.8]))]
    cfg = GraphConfig(closure_min_separation=10**6)  # no ICP search: closures given
    empty = [np.zeros((0, 2))] * n
    res = optimize(odo, empty, cfg, extra_closures=good + wrong)
    err_odo = np.hypot(*(odo[:, :2] - truth[:, :2]).T).max()
    err_opt = np.hypot(*(res.poses_xytheta[:, :2] - truth[:, :2]).T).max()
    assert err_odo > 1.0 and err_opt < 0.5 * err_odo
    res_bad = optimize(odo, empty, cfg, extra_closures=good)
    err_clean = np.hypot(*(res_bad.poses_xytheta[:, :2] - truth[:, :2]).T).max()
    assert err_opt < err_clean + 0.2  # the wrong closure barely moves the solution


def _room_with_boxes():
    return room_grid(11, 8, 0.05, boxes=[(2, 2, 3, 2.6), (6, 5, 6.4, 6.5), (7, 1, 8.5, 1.3),
                                         (3.5, 6, 4.5, 6.8), (9, 4, 9.5, 5)])


def _end_error(scans, truth, cfg):
    sm = ScanMatchOdometry.from_config(cfg)
    poses = np.array([sm.register(s).pose_xytheta for s in scans])
    e = relative(relative(poses[0], poses[-1]), relative(truth[0], truth[-1]))
    return np.hypot(e[0], e[1]), np.degrees(abs(e[2])), sm.stats


def test_scans_without_odometry_are_matched_from_constant_velocity_and_turn_seeds():
    # a laser-only bag: a robot drives straight, then turns left and, between two scans,
    # right (0.2 rad/scan each way). Constant velocity misses the start of the turn by 0.2 rad
    # and the reversal by 0.4 rad; ICP from it fails there, and the extra headings find the
    # turn
    from tests.helpers import drive_scans

    g = _room_with_boxes()
    yaw = np.concatenate([np.zeros(8), np.cumsum(np.full(4, 0.2))])
    yaw = np.concatenate([yaw, yaw[-1] - np.cumsum(np.full(4, 0.2))])
    truth = np.column_stack([2.0 + 0.1 * np.arange(len(yaw)), 3.5 + 0.03 * np.arange(len(yaw)),
                             yaw])
    scans = drive_scans(g, truth, max_range_m=8.0)
    for i, s in enumerate(scans):
        s.stamp_s, s.odom_pose_xytheta = 0.2 * i, None
    xy, deg, st = _end_error(scans, truth, IcpConfig(rescue=False))
    assert st["no_odometry"] == len(scans) - 1 and st["heading_seed"] >= 1
    assert st["fallback_bad_fit"] == 0 and st["icp"] == len(scans) - 1
    assert xy < 0.03 and deg < 0.5
    # without the extra headings the turn is lost (measured: 92 deg off at the end)
    xy0, deg0, st0 = _end_error(scans, truth, IcpConfig(heading_seeds=0, rescue=False))
    assert st0["fallback_bad_fit"] >= 1 and deg0 > 30
    # wheels that are right and ignored (use_odometry false) give the same as none at all
    with_wheels = drive_scans(g, truth, max_range_m=8.0)
    for i, s in enumerate(with_wheels):
        s.stamp_s = 0.2 * i
    xy1, deg1, st1 = _end_error(with_wheels, truth, IcpConfig(use_odometry=False))
    assert st1["no_odometry"] == len(scans) - 1
    assert (xy1, deg1) == pytest.approx((xy, deg))


@pytest.mark.parametrize("wheels", [True, False])
def test_a_gap_in_the_log_is_bridged_by_the_correlative_rescue(wheels):
    # ACES holds a 3 s gap over which the robot turned 84 deg; ICP from any nearby guess
    # fails there. The rescue searches the local map (+-1 m, any heading) and places the scan;
    # without it the pose follows the guess and the turn is lost for the rest of the run
    from tests.helpers import drive_scans

    g = _room_with_boxes()
    truth = np.array([[2.0 + 0.1 * i, 3.5, 0.0] for i in range(12)]
                     + [[3.3 + 0.1 * i, 3.6 + 0.1 * i, 1.4] for i in range(10)])
    scans = drive_scans(g, truth, max_range_m=8.0)
    for i, s in enumerate(scans):
        s.stamp_s = 0.2 * i + (3.0 if i >= 12 else 0.0)
        if wheels:  # the wheels slipped over the gap: they saw no turn
            if i >= 12:
                s.odom_pose_xytheta = compose(scans[11].odom_pose_xytheta,
                                              relative(truth[12], truth[i]))
        else:
            s.odom_pose_xytheta = None
    xy, deg, st = _end_error(scans, truth, IcpConfig())
    assert st["rescued"] == 1 and st["fallback_bad_fit"] == 0
    assert xy < 0.03 and deg < 0.5
    xy0, deg0, st0 = _end_error(scans, truth, IcpConfig(rescue=False))
    assert st0["fallback_bad_fit"] >= 1 and st0["rescued"] == 0
    assert deg0 > 30
