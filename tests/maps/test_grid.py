import numpy as np
import pytest

from gatmo.errors import MapError
from gatmo.maps.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid


def make():
    cells = np.full((4, 6), FREE, dtype=np.int8)
    cells[1, 2] = OCCUPIED
    cells[3, 5] = UNKNOWN
    return OccupancyGrid(cells, 0.5, (-1.0, 2.0, 0.0))


def test_world_cell_round_trip():
    g = make()
    cells = np.array([[0, 0], [2, 1], [5, 3]])
    centres = g.cell_to_world(cells)
    np.testing.assert_allclose(centres[0], [-0.75, 2.25])
    np.testing.assert_array_equal(g.world_to_cell(centres), cells)
    # a point just below the origin is outside
    assert not g.in_bounds(g.world_to_cell(np.array([[-1.0, 1.99]])))[0]


def test_value_at_and_masks():
    g = make()
    pts = g.cell_to_world(np.array([[2, 1], [5, 3], [0, 0], [100, 0]]))
    np.testing.assert_array_equal(g.value_at(pts), [OCCUPIED, UNKNOWN, FREE, UNKNOWN])
    assert g.occupied.sum() == 1 and g.unknown.sum() == 1 and g.free.sum() == 22
    assert g.extent_xy == (-1.0, 2.0, 2.0, 4.0)
    np.testing.assert_allclose(g.occupied_cells_world(), [[0.25, 2.75]])


def test_refuses_bad_grids():
    with pytest.raises(MapError, match="yaw"):
        OccupancyGrid(np.zeros((2, 2)), 0.1, (0.0, 0.0, 0.3))
    with pytest.raises(MapError, match="resolution"):
        OccupancyGrid(np.zeros((2, 2)), 0.0)
    with pytest.raises(MapError):
        OccupancyGrid(np.zeros((0, 2)), 0.1)


def test_equality_and_copy():
    g = make()
    h = g.copy()
    assert g == h
    h.cells[0, 0] = OCCUPIED
    assert g != h
