"""Matching helpers on hand-made shapes with known answers (gatmo.objects.matching)."""

from __future__ import annotations

import numpy as np
import pytest

from gatmo.geometry import transform_points
from gatmo.objects import GatmoConfig
from gatmo.objects.matching import extent_excess, match_points, min_rect
from gatmo.objects.objectmap import MapObject, shape_from_points

CFG = GatmoConfig()


def _outline(length_m: float, width_m: float, step_m: float = 0.01) -> np.ndarray:
    """Points (P, 2) on a rectangle's four sides, centred on the origin."""
    a = np.arange(-length_m / 2, length_m / 2 + 1e-9, step_m)
    b = np.arange(-width_m / 2, width_m / 2 + 1e-9, step_m)
    return np.vstack([np.c_[a, np.full_like(a, -width_m / 2)],
                      np.c_[a, np.full_like(a, width_m / 2)],
                      np.c_[np.full_like(b, -length_m / 2), b],
                      np.c_[np.full_like(b, length_m / 2), b]])


def _laser_built(length_m: float, width_m: float, pose) -> MapObject:
    """A piece as the simulator's maps have it (``gatmo.datasets.sim.world``): every 0.05 m
    cell it overlaps, filled."""
    a = np.arange(-length_m / 2, length_m / 2 + 1e-9, 0.0125)
    b = np.arange(-width_m / 2, width_m / 2 + 1e-9, 0.0125)
    pts = transform_points(np.asarray(pose), np.stack(np.meshgrid(a, b), -1).reshape(-1, 2))
    cells = (np.unique(np.floor(pts / 0.05).astype(int), axis=0) + 0.5) * 0.05
    shape, edge, p0 = shape_from_points(cells, 0.05)
    return MapObject(1, None, "A", p0, shape, edge, resolution_m=0.05)


def _corner_scans(length_m: float, width_m: float, pose, rng, n: int = 9) -> list:
    """``n`` scans of a box seen from a corner: two of its sides, 2-4 cm between returns,
    1 cm range noise, map frame."""
    out = []
    for _ in range(n):
        step = rng.uniform(0.02, 0.04)
        a = np.arange(rng.uniform(0, step), length_m, step)
        b = np.arange(rng.uniform(0, step), width_m, step)
        p = np.vstack([np.c_[a - length_m / 2, np.full_like(a, -width_m / 2)],
                       np.c_[np.full_like(b, length_m / 2), b - width_m / 2]])
        out.append(transform_points(np.asarray(pose), p + rng.normal(0.0, 0.01, p.shape)))
    return out


@pytest.mark.parametrize("yaw", [0.0, 0.4, np.pi / 4])
def test_min_rect_follows_the_sides_of_a_turned_box_and_of_an_l(yaw):
    rng = np.random.default_rng(1)
    pts = transform_points(np.array([2.0, 1.0, yaw]), _outline(0.9, 0.45))
    centre, axes, ext = min_rect(pts)
    np.testing.assert_allclose(np.sort(ext), [0.45, 0.9], atol=1e-6)
    np.testing.assert_allclose(centre, [2.0, 1.0], atol=1e-6)
    long_axis = axes[int(np.argmax(ext))]
    assert abs(np.sin(np.arctan2(long_axis[1], long_axis[0]) - yaw)) < 1e-6
    # two sides of a square seen from its corner: the least rectangle lies along them (the
    # least area would as well lie along the hypotenuse, 0.71 x 0.35 m)
    corner = _corner_scans(0.5, 0.5, (2.0, 1.0, yaw), rng, n=1)[0]
    _, _, ext = min_rect(corner)
    assert np.all(np.abs(ext - 0.5) < 0.05), ext


def test_extent_excess_tells_a_box_from_a_footstool_the_edge_score_cannot():
    # a 0.45 m footstool in the map; a 0.50 m box and a 0.45 m footstool seen from a corner
    # elsewhere. Both fit the footstool's blurred edges (score above match_min_score); the
    # box's sides, one scan at a time, run past the footstool's outline by its 5 cm more.
    # How far the map's cells reach past a surface (0 to a cell, by where the grid falls)
    # and the returns' noise shift both verdicts alike
    rng = np.random.default_rng(7)
    for yaw, dx in ((0.0, 0.0), (0.0, 0.021), (0.3, 0.013), (0.9, 0.037)):
        stool = _laser_built(0.45, 0.45, (3.0 + dx, 2.0 + dx / 2, yaw))
        verdicts = {}
        for label, size in (("box", 0.5), ("footstool", 0.45)):
            scans = _corner_scans(size, size, (5.0, 4.0, yaw + 0.2), rng)
            mt = match_points(np.vstack(scans), stool, CFG, prior_yaw=yaw)
            assert mt.score >= CFG.match_min_score, (label, yaw, mt.score)
            verdicts[label] = extent_excess(stool, mt.pose_xytheta, scans)
        assert verdicts["box"] - verdicts["footstool"] > 0.03, (yaw, dx, verdicts)
        assert verdicts["footstool"] < 0.04, (yaw, dx, verdicts)


def test_extent_excess_is_none_without_returns_near_the_object_and_ignores_far_ones():
    rng = np.random.default_rng(3)
    stool = _laser_built(0.45, 0.45, (3.0, 2.0, 0.0))
    far = [np.array([[9.0, 9.0], [9.1, 9.0], [9.2, 9.0]])]
    assert extent_excess(stool, stool.pose_xytheta, far) is None
    assert extent_excess(stool, stool.pose_xytheta, [np.zeros((2, 2))]) is None
    # its own sides plus a return 1 m away in every scan: the far return does not count
    own = _corner_scans(0.45, 0.45, (3.0, 2.0, 0.0), rng)
    with_far = [np.vstack([s, [[4.0, 2.0]]]) for s in own]
    assert extent_excess(stool, stool.pose_xytheta, with_far) == pytest.approx(
        extent_excess(stool, stool.pose_xytheta, own))
    assert extent_excess(stool, stool.pose_xytheta, own) < 0.04


def test_a_chairs_lines_are_found_once_for_all_candidates_and_never_served_stale(monkeypatch):
    """candidate_rotations keeps the last few point sets' lines (one chair is matched against
    every candidate object in turn): the same answer as finding them afresh, found once per
    point set, and a set changed in place is a new set."""
    from gatmo.objects import matching

    rng = np.random.default_rng(3)
    box = _laser_built(0.9, 0.45, [0.0, 0.0, 0.0])
    stool = _laser_built(0.45, 0.45, [0.0, 0.0, 0.0])
    fields = [matching.EdgeField(o, CFG.match_edge_sigma_m) for o in (box, stool)]
    calls = []
    real = matching.line_directions
    monkeypatch.setattr(matching, "line_directions",
                        lambda p, *a, **k: calls.append(1) or real(p, *a, **k))
    monkeypatch.setattr(matching, "_AXES", matching._AxesCache(size=2))
    pts = np.vstack(_corner_scans(0.9, 0.45, [3.0, 1.0, 0.5], rng, n=3))

    def fresh(points, field):
        # the rotations as computed before the cache: lines and principal axis afresh
        cands = []
        for a in real(points):
            for o in field.lines:
                cands += [a - o, a - o + np.pi]
        a_p = matching.principal_angle(points)
        cands += [a_p - field.principal + k * np.pi / 2 for k in range(4)]
        out = []
        for th in cands:
            th = float(matching.wrap_angle(th))
            if all(abs(matching.wrap_angle(th - o)) > np.radians(2.5) for o in out):
                out.append(th)
        return np.array(out)

    for field in fields * 2:
        np.testing.assert_array_equal(matching.candidate_rotations(pts, field),
                                      fresh(pts, field))
    assert len(calls) == 1
    turned = transform_points(np.array([0.0, 0.0, 0.7]), pts)
    pts[:] = turned  # the same array, new contents
    np.testing.assert_array_equal(matching.candidate_rotations(pts, fields[0]),
                                  fresh(turned, fields[0]))
    assert len(calls) == 2
    # a bounded cache: the oldest set leaves first
    for k in range(3):
        matching.candidate_rotations(pts + k, fields[0])
    assert len(matching._AXES._d) == 2


@pytest.mark.parametrize("levels", [None, 7])
def test_best_first_is_a_stable_sorts_head(levels):
    """The coarse search's picks (matching._best_first) are the head of a stable sort, highest
    first, whether or not scores tie (quantized scores tie often: ``levels``)."""
    from gatmo.objects.matching import _best_first

    rng = np.random.default_rng(5)
    for n in (1, 5, 200, 201, 5000):
        s = rng.random(n)
        if levels:
            s = np.round(s * levels) / levels
        want = np.argsort(-s, kind="stable")[:200]
        np.testing.assert_array_equal(_best_first(s, 200), want)
