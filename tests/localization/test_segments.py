"""segment_balanced: one long surface in view cannot outvote the other things in view."""

from __future__ import annotations

import numpy as np

from gatmo.localization import AmclConfig
from gatmo.localization.sensor import SensorModel, segment_weights
from gatmo.maps.likelihood import LikelihoodField
from tests.helpers import make_scan, room_grid


def test_segment_weights_cap_each_segment():
    a = np.radians(np.arange(12.0))
    r = np.array([1.0] * 8 + [3.0, 3.1] + [2.0, 2.0])
    w = segment_weights(r, a, jump_m=0.3, max_beams=4)
    np.testing.assert_allclose(w, [0.5] * 8 + [1.0] * 4)
    # a gap in angle (beams dropped between) starts a new segment too
    a2 = np.radians(np.r_[np.arange(6.0), np.arange(10.0, 16.0)])
    w2 = segment_weights(np.ones(12), a2, jump_m=0.3, max_beams=3)
    np.testing.assert_allclose(w2, [0.5] * 12)
    assert segment_weights(np.zeros(0), np.zeros(0), 0.3, 4).shape == (0,)


def _bench_hall(shift_m: float):
    """A 20 m hall: a 2.4 m bench 0.9 m ahead of the robot, moved away from it by
    ``shift_m``, and three boxes 2.5-3 m away that stayed."""
    boxes = [(6.5, 3.4, 7.1, 4.0), (11.0, 3.0, 11.6, 3.6), (11.4, 6.0, 12.0, 6.6)]
    bench = (7.8, 5.9 + shift_m, 10.2, 6.2 + shift_m)
    return room_grid(20.0, 12.0, 0.05, boxes=[*boxes, bench])


def test_a_moved_bench_does_not_outvote_the_pieces_that_stayed():
    # the robot at (9, 5) sees the bench, moved 0.6 m away from it, from close by (22 of the
    # 36 beams weighed), and three boxes that stayed. Plain likelihood_field_prob prefers the
    # pose 0.6 m back, where the bench fits its old place; balanced per segment, the true pose
    mapped, real = _bench_hall(0.0), _bench_hall(0.6)
    truth = np.array([9.0, 5.0, 0.0])
    wrong = truth - np.array([0.0, 0.6, 0.0])
    scan = make_scan(real, truth, n_beams=361, fov_rad=2 * np.pi, max_range_m=4.0)
    best = {}
    for balanced in (False, True):
        cfg = AmclConfig(laser_model="likelihood_field_prob", sigma_hit_m=0.1, z_hit=0.95,
                         z_rand=0.05, max_beams=90, segment_balanced=balanced)
        model = SensorModel(LikelihoodField(mapped, 2.0), cfg)
        logw, n = model.weigh(np.stack([truth, wrong]), scan, False)
        assert n > 0
        best[balanced] = int(np.argmax(logw))
    assert best == {False: 1, True: 0}
