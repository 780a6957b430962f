"""Beams that end in unmapped space: which ones, the kernel against its numpy reference, and the
localizer driving out of the map through a door and back."""

from __future__ import annotations

import numpy as np
import pytest

from gatmo.localization import AmclConfig, MonteCarloLocalizer
from gatmo.localization import _kernels as K
from gatmo.localization.sensor import SensorModel, select_beams, unmapped_beams_reference
from gatmo.maps.grid import OCCUPIED, UNKNOWN
from gatmo.maps.likelihood import LikelihoodField
from tests.helpers import drive_scans, make_scan, room_grid

RES = 0.05
DOOR_Y = (3.4, 4.6)


def _worlds():
    """(real, mapped): a 10 x 8 m hall with a door in its east wall (x 10-10.1) into a 10 x 8 m
    annex with two boxes; in the map the annex is unknown."""
    real = room_grid(20, 8, RES, boxes=[(10.0, 0.0, 10.1, DOOR_Y[0]), (10.0, DOOR_Y[1], 10.1, 8.0),
                                        (2.0, 1.0, 2.6, 1.6), (4.0, 6.0, 4.4, 7.0),
                                        (13.0, 2.0, 13.5, 2.5), (16.0, 5.5, 16.8, 6.0)])
    mapped = real.copy()
    mapped.cells[:, int(round(10.1 / RES)):] = UNKNOWN
    return real, mapped


def _model(grid, **kw):
    cfg = AmclConfig(**(dict(laser_model="likelihood_field_prob", sigma_hit_m=0.1, z_hit=0.95,
                             z_rand=0.05) | kw))
    return SensorModel(LikelihoodField(grid.copy(), 2.0), cfg), cfg


def test_unmapped_kernel_matches_reference():
    real, mapped = _worlds()
    model, cfg = _model(mapped)
    rng = np.random.default_rng(0)
    parts = np.column_stack([rng.uniform(-1, 21, 300), rng.uniform(-1, 9, 300),
                             rng.uniform(-np.pi, np.pi, 300)])
    lp = np.array([0.1, 0.0, 0.02])
    angles = np.linspace(-np.pi / 2, np.pi / 2, 37)
    ranges = rng.uniform(0.05, 6.0, 37)
    table = model._unmapped_table()
    got = K.unmapped_beams_kernel(parts, lp, ranges, angles, ranges * np.cos(angles),
                                  ranges * np.sin(angles), table, mapped.cells, RES, 0.0, 0.0, 0.3)
    ref = unmapped_beams_reference(parts, lp, ranges, angles, mapped, table, 0.3)
    np.testing.assert_array_equal(got, ref)
    assert 0 < got.sum() < 300 * 37


def test_which_beams_are_unmapped():
    real, mapped = _worlds()
    model, _ = _model(mapped)
    table = model._unmapped_table()
    # unknown annex cells beyond 3 sigma (0.3 m) of the east wall; the wall and the band next
    # to it are mapped
    assert table[40, int(11.0 / RES)] == 1 and table[40, int(10.3 / RES)] == 0
    assert table[40, int(5.0 / RES)] == 0
    one = np.array([[8.0, 4.0, 0.0]])  # in the hall, 2 m west of the door, facing it
    lp = np.zeros(3)
    angles = np.array([0.0, np.pi / 2, np.radians(20.0)])
    # through the door 4 m into the annex; the north wall (3.9 m); 4 m north-east: beyond the
    # east wall, in the annex, but the ray crosses the wall (the map contradicts it)
    ranges = np.array([4.0, 3.9, 4.0])
    np.testing.assert_array_equal(model.mapped_beams(one, lp, ranges, angles),
                                  [False, True, True])


def test_scans_from_outside_the_map_are_not_weighed():
    real, mapped = _worlds()
    model, cfg = _model(mapped)
    rng = np.random.default_rng(1)
    truth = np.array([15.0, 4.0, 0.3])
    scan = make_scan(real, truth, n_beams=181, max_range_m=4.0, noise_m=0.01)
    parts = truth + rng.normal(0, [0.1, 0.1, 0.05], size=(200, 3))
    logw, n = model.weigh(parts, scan, False)
    assert n == 0 and model.last_unmapped_beams > 0 and np.all(logw == 0)
    # AMCL's behaviour: every beam weighed (as a miss)
    amcl, _ = _model(mapped, skip_unmapped_beams=False)
    assert amcl.weigh(parts, scan, False)[1] > 0
    # in the door, facing the hall: every beam ends on the map and is weighed
    inside = np.array([10.05, 4.0, np.pi])
    scan = make_scan(real, inside, n_beams=181, max_range_m=4.0)
    _, n = model.weigh(inside + rng.normal(0, 0.05, size=(50, 3)), scan, False)
    r, _, _ = select_beams(scan, cfg.max_beams, None, None, keep_max_range=False)
    assert n == len(r) and model.last_unmapped_beams == 0


def test_part_of_a_scan_into_unmapped_space():
    real, mapped = _worlds()
    model, cfg = _model(mapped, min_mapped_beam_fraction=0.2)
    pose = np.array([9.0, 4.0, 0.0])  # 1 m west of the door, facing it: the annex through it
    scan = make_scan(real, pose, n_beams=181, max_range_m=8.0)
    r, a, _ = select_beams(scan, cfg.max_beams, None, None, keep_max_range=False)
    keep = model.mapped_beams(pose[None], np.zeros(3), r, a)
    _, n = model.weigh(pose[None], scan, False)
    assert 0 < (~keep).sum() < len(r) and n == keep.sum()
    assert model.last_unmapped_beams == (~keep).sum()
    # the left-out beams are those through the door
    ends_x = pose[0] + r * np.cos(a)
    assert np.all(ends_x[~keep] > 10.1)
    # above min_mapped_beam_fraction of unmapped beams the scan is not weighed at all
    strict, _ = _model(mapped, min_mapped_beam_fraction=0.99)
    assert strict.weigh(pose[None], scan, False)[1] == 0


def test_unmapped_table_follows_map_changes():
    real, mapped = _worlds()
    field = LikelihoodField(mapped.copy(), 2.0)
    cfg = AmclConfig(laser_model="likelihood_field_prob", sigma_hit_m=0.1)
    model = SensorModel(field, cfg)
    model._unmapped_table()
    for k, value in enumerate([UNKNOWN, OCCUPIED, 0]):
        field.update_region(np.full((20, 30), value, dtype=np.int8), 40 + 30 * k, 60)
        fresh = SensorModel(LikelihoodField(field.grid.copy(), 2.0), cfg)._unmapped_table()
        np.testing.assert_array_equal(model._unmapped_table(), fresh)


def _excursion(real, odom_scale=1.01):
    """Poses (0.1 m steps, turns on the spot in 0.1 rad steps) from the hall out through the
    door, round the annex and back, with odometry 1 % long."""
    way = np.array([[6.0, 4.0], [15.0, 4.0], [15.0, 4.6], [6.0, 4.6]])
    pts = [[6.0, 4.0, 0.0]]
    for a, b in zip(way[:-1], way[1:], strict=True):
        th = np.arctan2(*(b - a)[::-1])
        turn = np.angle(np.exp(1j * (th - pts[-1][2])))
        k = int(np.ceil(abs(turn) / 0.1))
        pts += [[*a, pts[-1][2] + turn * (i + 1) / k] for i in range(k)]
        n = int(np.ceil(np.hypot(*(b - a)) / 0.1))
        pts += [[*(a + (b - a) * t), th] for t in np.arange(1, n + 1) / n]
    return drive_scans(real, np.array(pts), odom_scale=odom_scale, max_range_m=4.0, seed=3)


def test_leaving_the_map_and_returning_keeps_track():
    # (recovery on: test_recovery_does_not_inject_while_the_scans_gain_beams)
    real, mapped = _worlds()
    scans = _excursion(real)
    cfg = AmclConfig(laser_model="likelihood_field_prob", sigma_hit_m=0.1, z_hit=0.95,
                     z_rand=0.05, alpha1=0.05, alpha2=0.05, alpha3=0.05, alpha4=0.05,
                     update_min_d_m=0.1, update_min_a_rad=0.1, min_particles=500,
                     max_particles=3000)
    loc = MonteCarloLocalizer(mapped, cfg, np.random.default_rng(0))
    loc.set_initial_pose(scans[0].gt_pose_xytheta, np.diag([0.01, 0.01, 0.005]))
    err = np.array([np.hypot(*(loc.update(s.odom_pose_xytheta, s).pose_xytheta[:2]
                               - s.gt_pose_xytheta[:2])) for s in scans])
    gx = np.array([s.gt_pose_xytheta[0] for s in scans])
    outside = gx > 10.6
    assert outside.sum() > 80
    assert loc.stats.unmapped_beams > 0 and loc.stats.skipped_no_valid_beams > 50
    # outside the map the particles follow odometry (1 % long: ~0.1 m over 9 m), back inside
    # the map the filter tracks again
    assert err[outside].max() < 0.3
    back = np.flatnonzero(outside)[-1] + 1
    assert np.median(err[back + 20 :]) < 0.1 and err[back:].max() < 0.3
    # AMCL's way (every beam weighed, the unmapped ones as misses) drags the particles off
    loc = MonteCarloLocalizer(mapped, cfg.model_copy(update={"skip_unmapped_beams": False}),
                              np.random.default_rng(0))
    loc.set_initial_pose(scans[0].gt_pose_xytheta, np.diag([0.01, 0.01, 0.005]))
    err = np.array([np.hypot(*(loc.update(s.odom_pose_xytheta, s).pose_xytheta[:2]
                               - s.gt_pose_xytheta[:2])) for s in scans])
    assert err[outside].max() > 1.0


@pytest.mark.parametrize("per_beam", [True, False], ids=["per-beam", "amcl-average"])
def test_recovery_does_not_inject_while_the_scans_gain_beams(per_beam):
    # Recovery on (AMCL's alphas). Driving into the hall the scans gain beams (max-range ones
    # drop out), and with a product over beams the scan's likelihood falls with each beam
    # added: AMCL's raw average reads that as being lost and injects from the start; the
    # averages per beam (recovery_per_beam) do not, and the robot is tracked out and back.
    real, mapped = _worlds()
    scans = _excursion(real)
    cfg = AmclConfig(laser_model="likelihood_field_prob", sigma_hit_m=0.1, z_hit=0.95,
                     z_rand=0.05, alpha1=0.05, alpha2=0.05, alpha3=0.05, alpha4=0.05,
                     update_min_d_m=0.1, update_min_a_rad=0.1, min_particles=500,
                     max_particles=3000, recovery_alpha_slow=0.001, recovery_alpha_fast=0.1,
                     recovery_per_beam=per_beam)
    loc = MonteCarloLocalizer(mapped, cfg, np.random.default_rng(1))
    loc.set_initial_pose(scans[0].gt_pose_xytheta, np.diag([0.01, 0.01, 0.005]))
    err = np.array([np.hypot(*(loc.update(s.odom_pose_xytheta, s).pose_xytheta[:2]
                               - s.gt_pose_xytheta[:2])) for s in scans])
    outside = np.array([s.gt_pose_xytheta[0] for s in scans]) > 10.6
    if per_beam:  # seeds 0-3: 0-65 particles injected, at most 0.21 m off
        assert loc.stats.random_injected < 1000
        assert err.max() < 0.3
    else:  # seeds 0-3: 160-178 thousand injected, 13.8-14.6 m off outside
        assert loc.stats.random_injected > 10_000
        assert err[outside].max() > 1.0
