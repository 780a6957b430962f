"""Scans the map does not explain (``min_explained_beam_fraction``): held back, the particles
coast on odometry, for at most ``max_coast_m`` of travel."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from gatmo.localization import AmclConfig, MonteCarloLocalizer
from gatmo.localization.sensor import SensorModel
from gatmo.maps.likelihood import LikelihoodField
from tests.helpers import drive_scans, make_scan, room_grid

RES = 0.05
ROUTE_Y = 5.0


def _boxes(xs) -> list[tuple[float, float, float, float]]:
    """0.5 x 0.4 m boxes beside the route (y 5), alternately north and south of it."""
    out = []
    for i, x in enumerate(xs):
        y = ROUTE_Y + 1.5 if i % 2 == 0 else ROUTE_Y - 1.9
        out.append((x, y, x + 0.5, y + 0.4))
    return out


def _worlds():
    """(real, mapped): a 20 x 10 m hall, its walls beyond a 3.5 m laser's reach from the route,
    boxes every 1.5 m beside it. In the map the boxes of x 8-13 stand 1.5 m further from the
    route: there the robot sees nothing the map shows."""
    xs = np.arange(2.5, 17.0, 1.5)
    real = room_grid(20, 10, RES, boxes=_boxes(xs))
    moved = []
    for x0, y0, x1, y1 in _boxes(xs):
        dy = 0.0 if not 8.0 <= x0 <= 13.0 else (1.5 if y0 > ROUTE_Y else -1.5)
        moved.append((x0, y0 + dy, x1, y1 + dy))
    return real, room_grid(20, 10, RES, boxes=moved)


def _cfg(**kw) -> AmclConfig:
    return AmclConfig(**(dict(laser_model="likelihood_field_prob", sigma_hit_m=0.1, z_hit=0.95,
                              z_rand=0.05, alpha1=0.05, alpha2=0.05, alpha3=0.05, alpha4=0.05,
                              update_min_d_m=0.1, update_min_a_rad=0.1, min_particles=500,
                              max_particles=2000) | kw))


def _drive(real, odom_scale=1.01):
    xs = np.arange(2.0, 17.0, 0.1)
    true = np.column_stack([xs, np.full_like(xs, ROUTE_Y), np.zeros_like(xs)])
    return drive_scans(real, true, odom_scale=odom_scale, max_range_m=3.5, seed=5)


@functools.cache
def _scenario():
    """(mapped, scans along the route, the true x of each scan), built once for the module."""
    real, mapped = _worlds()
    scans = _drive(real)
    return mapped, scans, np.array([s.gt_pose_xytheta[0] for s in scans])


def test_unexplained_scan_is_held_back():
    real, mapped = _worlds()
    model = SensorModel(LikelihoodField(mapped.copy(), 2.0), _cfg(min_explained_beam_fraction=0.5))
    rng = np.random.default_rng(0)
    for x, gated in ((10.5, True), (4.5, False)):  # among moved boxes / unmoved ones
        truth = np.array([x, ROUTE_Y, 0.0])
        scan = make_scan(real, truth, n_beams=181, max_range_m=3.5)
        parts = truth + rng.normal(0, [0.05, 0.05, 0.02], size=(100, 3))
        logw, n = model.weigh(parts, scan, True, gate_unexplained=True)
        assert model.last_gated is gated and (n == 0) is gated
        assert (model.last_explained_fraction < 0.5) is gated
    # only when the localizer asks (converged, within max_coast_m)
    scan = make_scan(real, np.array([10.5, ROUTE_Y, 0.0]), n_beams=181, max_range_m=3.5)
    parts = np.array([10.5, ROUTE_Y, 0.0]) + rng.normal(0, 0.05, size=(100, 3))
    assert model.weigh(parts, scan, True, gate_unexplained=False)[1] > 0
    assert not model.last_gated
    # off (AMCL): weighed
    amcl = SensorModel(LikelihoodField(mapped.copy(), 2.0), _cfg())
    assert amcl.weigh(parts, scan, True, gate_unexplained=True)[1] > 0 and not amcl.last_gated


def _run(cfg, scans, mapped):
    loc = MonteCarloLocalizer(mapped, cfg, np.random.default_rng(0))
    loc.set_initial_pose(scans[0].gt_pose_xytheta, np.diag([0.01, 0.01, 0.005]))
    err, weighed = [], []
    for s in scans:
        est = loc.update(s.odom_pose_xytheta, s)
        err.append(np.hypot(*(est.pose_xytheta[:2] - s.gt_pose_xytheta[:2])))
        weighed.append(est.updated)
    return loc, np.array(err), np.array(weighed)


def test_filter_coasts_through_unexplained_stretch_and_recaptures():
    mapped, scans, gx = _scenario()
    loc, err, weighed = _run(_cfg(min_explained_beam_fraction=0.5, max_coast_m=10.0), scans,
                             mapped)
    moved = (gx > 7.5) & (gx < 12.0)  # only boxes the map has elsewhere in view
    assert loc.stats.unexplained_skipped >= 30
    assert not weighed[moved].any()
    # on odometry (1 % long) and the heading the filter had on entering: 0.3 m
    assert err[moved].max() < 0.4
    # boxes the map has right are weighed again, and the filter tracks
    after = gx > 14.0
    assert weighed[after].sum() >= 10 and np.median(err[after]) < 0.1
    # AMCL weighs every scan: the particles lock onto the boxes where the map has them, 1.5 m
    # to the side, and stay there
    _, err, weighed = _run(_cfg(), scans, mapped)
    assert weighed[moved].all()
    assert np.median(err[gx > 10.0]) > 1.0


def test_coasting_is_bounded():
    mapped, scans, gx = _scenario()
    loc, err, weighed = _run(_cfg(min_explained_beam_fraction=0.5, max_coast_m=1.0), scans,
                             mapped)
    moved = (gx > 9.5) & (gx < 12.5)
    # after 1 m of odometry alone the scans are weighed again, as AMCL weighs them
    assert weighed[moved].sum() >= 5
    skipped_bounded = loc.stats.unexplained_skipped
    loc, _, _ = _run(_cfg(min_explained_beam_fraction=0.5, max_coast_m=10.0), scans, mapped)
    assert skipped_bounded < loc.stats.unexplained_skipped



def _along_worlds():
    """(real, mapped) as :func:`_worlds`, but in the map the boxes of x 8-13 stand 0.7 m further
    along the route (east): a filter slid 0.7 m east explains the scans there."""
    xs = np.arange(2.5, 17.0, 1.5)
    real = room_grid(20, 10, RES, boxes=_boxes(xs))
    moved = [(x0 + 0.7, y0, x1 + 0.7, y1) if 8.0 <= x0 <= 13.0 else (x0, y0, x1, y1)
             for x0, y0, x1, y1 in _boxes(xs)]
    return real, room_grid(20, 10, RES, boxes=moved)


def test_explained_at_the_prediction_ignores_particles_on_a_wrong_alignment():
    real, mapped = _along_worlds()
    truth = np.array([11.0, ROUTE_Y, 0.0])
    scan = make_scan(real, truth, n_beams=181, max_range_m=3.5)
    rng = np.random.default_rng(1)
    # most particles at the true pose, a fifth slid 0.7 m east onto the boxes' old places
    parts = truth + rng.normal(0, [0.03, 0.03, 0.01], size=(200, 3))
    parts[:40, 0] += 0.7
    field = LikelihoodField(mapped.copy(), 2.0)
    best = SensorModel(field, _cfg(min_explained_beam_fraction=0.5))
    best.weigh(parts, scan, True, gate_unexplained=True)
    assert best.last_explained_fraction > 0.5 and not best.last_gated
    at = SensorModel(field, _cfg(min_explained_beam_fraction=0.5, explained_at="prediction"))
    _, n = at.weigh(parts, scan, True, gate_unexplained=True, predicted_xytheta=truth)
    assert at.last_explained_fraction < 0.2 and at.last_gated and n == 0
    # at a place whose boxes the map has right, the prediction explains the scan
    truth = np.array([4.5, ROUTE_Y, 0.0])
    scan = make_scan(real, truth, n_beams=181, max_range_m=3.5)
    _, n = at.weigh(truth + rng.normal(0, 0.03, size=(200, 3)), scan, True,
                    gate_unexplained=True, predicted_xytheta=truth)
    assert at.last_explained_fraction > 0.8 and not at.last_gated and n > 0


def test_withheld_beams_count_as_unexplained():
    real, mapped = _along_worlds()
    truth = np.array([12.8, ROUTE_Y, 0.0])
    scan = make_scan(real, truth, n_beams=181, max_range_m=3.5)
    model = SensorModel(LikelihoodField(mapped.copy(), 2.0),
                        _cfg(min_explained_beam_fraction=0.5, explained_at="prediction",
                             max_beams=181))
    # a caller (the full stack) withholds the returns of the boxes moved since the map was made
    # (x < 14) as unexplained; those of the two boxes beyond are left
    pts_x = truth[0] + scan.ranges_m * np.cos(scan.angles_rad)
    withheld = scan.valid & (pts_x < 14.0)
    kept = scan.valid & ~withheld
    ranges = np.where(withheld, np.nan, scan.ranges_m)
    masked = type(scan)(**{**scan.__dict__, "ranges_m": ranges})
    parts = truth + np.random.default_rng(2).normal(0, 0.03, size=(100, 3))
    model.weigh(parts, masked, True, gate_unexplained=True, predicted_xytheta=truth)
    without = model.last_explained_fraction
    assert without > 0.9 and not model.last_gated  # the returns left fit the map
    model.weigh(parts, masked, True, gate_unexplained=True, predicted_xytheta=truth,
                withheld=withheld)
    assert model.last_explained_fraction == pytest.approx(without * kept.sum() / scan.valid.sum())
    assert model.last_explained_fraction < 0.5 and model.last_gated
