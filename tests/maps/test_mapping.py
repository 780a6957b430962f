"""Mapping with known poses reproduces the room it scanned."""

from __future__ import annotations

import numpy as np

from gatmo.maps.mapping import RenderConfig, render_map
from tests.helpers import make_scan, room_grid


def test_render_map_of_a_room_matches_the_room():
    g = room_grid(8, 6, 0.05, boxes=[(3, 2, 3.6, 2.8)])
    poses = np.array([[1.5, 1.5, 0.3], [6.0, 4.5, 2.5], [1.5, 4.5, -0.8], [6.5, 1.2, 2.0]])
    scans = [make_scan(g, p, n_beams=721, fov_rad=2 * np.pi * 0.999, max_range_m=12)
             for p in poses]
    m = render_map(scans, poses, RenderConfig(max_range_m=12))
    occ = m.occupied_cells_world()
    truth = g.value_at(occ)
    assert np.mean(truth == 100) > 0.95  # what the map calls occupied is occupied
    free = m.free_cells_world()
    assert np.mean(g.value_at(free) == 0) > 0.99
    assert m.value_at(np.array([[3.3, 2.4]]))[0] != 0  # the box interior is never seen free
