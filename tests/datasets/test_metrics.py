"""Object sightings and visits (gatmo.datasets.metrics): the real-log check of what GATMO added."""

import numpy as np

from gatmo.datasets.metrics import object_sightings, visits


def _box(cx, cy, half=0.15, cell=0.05):
    g = np.arange(-half, half + 1e-9, cell)
    return np.array([[cx + x, cy + y] for x in g for y in g])


def _scan_of(boxes, laser_xytheta, angles, max_range=8.0):
    """Ranges a laser at ``laser_xytheta`` measures to square boxes (centre, half size):
    brute-force march along each beam."""
    x, y, th = laser_xytheta
    r = np.full(len(angles), np.inf)
    steps = np.arange(0.0, max_range, 0.005)
    for i, a in enumerate(angles):
        px, py = x + steps * np.cos(th + a), y + steps * np.sin(th + a)
        inside = np.zeros(len(steps), bool)
        for cx, cy, h in boxes:
            inside |= (np.abs(px - cx) <= h) & (np.abs(py - cy) <= h)
        if inside.any():
            r[i] = steps[np.argmax(inside)]
    return r, np.isfinite(r)


ANGLES = np.radians(np.arange(-90.0, 90.5, 1.0))


def test_a_box_that_stands_is_hit_and_one_that_left_is_passed():
    cells = _box(3.0, 0.4)
    laser = np.array([0.0, 0.0, 0.1])
    r, ok = _scan_of([(3.0, 0.4, 0.175), (9.0, 0.0, 3.0)], laser, ANGLES)  # the box, a wall
    hits, passes = object_sightings(cells, laser, ANGLES, r, ok, max_range_m=8.0)
    assert hits >= 4 and passes == 0
    r, ok = _scan_of([(9.0, 0.0, 3.0)], laser, ANGLES)  # the box has gone: the wall behind
    hits, passes = object_sightings(cells, laser, ANGLES, r, ok, max_range_m=8.0)
    assert hits == 0 and passes >= 4
    r, ok = _scan_of([], laser, ANGLES)  # nothing behind: no return is a pass too
    assert object_sightings(cells, laser, ANGLES, r, ok, max_range_m=8.0) == (0, passes)


def test_a_box_behind_the_laser_or_hidden_by_another_is_not_seen():
    cells = _box(-3.0, 0.0)
    r, ok = _scan_of([(9.0, 0.0, 3.0)], np.zeros(3), ANGLES)
    assert object_sightings(cells, np.zeros(3), ANGLES, r, ok, max_range_m=8.0) == (0, 0)
    # a box in front (at 1.5 m) hides one at 3 m: its beams end before it, neither hit nor pass
    r, ok = _scan_of([(1.5, 0.0, 0.3), (3.0, 0.0, 0.175)], np.zeros(3), ANGLES)
    assert object_sightings(_box(3.0, 0.0), np.zeros(3), ANGLES, r, ok,
                            max_range_m=8.0) == (0, 0)


def test_visits_split_at_gaps():
    t = np.arange(20, dtype=float) * 10.0  # a scan every 10 s
    seen = np.zeros(20, bool)
    seen[[1, 2, 3, 9, 10, 15]] = True
    assert visits(t, seen, gap_s=30.0) == [(1, 3), (9, 10), (15, 15)]
    assert visits(t, seen, gap_s=100.0) == [(1, 15)]
    assert visits(t, np.zeros(20, bool)) == []
