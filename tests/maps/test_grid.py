import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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


@settings(max_examples=100, deadline=None)
@given(data=st.data(), h=st.integers(1, 40), w=st.integers(1, 40),
       n=st.integers(0, 300), dtype=st.sampled_from([np.int32, np.int64, np.int16]))
def test_add_counts_is_np_add_at(data, h, w, n, dtype):
    # GATMO's per-scan ray counts (seen free, passed, hits): the bincount form must count
    # exactly as np.add.at, repeated cells included, and touch nothing else
    from gatmo.maps.grid import add_counts

    iy = np.array(data.draw(st.lists(st.integers(0, h - 1), min_size=n, max_size=n)), np.int64)
    ix = np.array(data.draw(st.lists(st.integers(0, w - 1), min_size=n, max_size=n)), np.int64)
    start = np.array(data.draw(st.lists(st.integers(0, 100), min_size=h * w, max_size=h * w)),
                     dtype).reshape(h, w)
    want, got = start.copy(), start.copy()
    np.add.at(want, (iy, ix), 1)
    add_counts(got, iy, ix)
    np.testing.assert_array_equal(got, want)
    assert got.dtype == dtype
