"""The mapper's whole-grid operations done within windows (gatmo.objects.mapper): each must
give what the whole-grid operation gives, at the grid's borders too."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from gatmo.objects.mapper import _changed_regions, _dilated, _max3x3_at, _window


def test_the_3x3_maximum_at_cells_is_the_maximum_filter_there():
    rng = np.random.default_rng(0)
    counts = rng.poisson(0.3, size=(40, 55)).astype(np.int32)
    cy, cx = np.meshgrid(np.arange(40), np.arange(55), indexing="ij")
    want = ndimage.maximum_filter(counts, size=3)
    np.testing.assert_array_equal(_max3x3_at(counts, cy.ravel(), cx.ravel()), want.ravel())


def test_window_is_the_grown_bounding_box_clipped_to_the_grid():
    m = np.zeros((10, 12), dtype=bool)
    assert _window(m, 2) is None
    m[1, 9] = m[4, 3] = True
    assert _window(m, 2) == (slice(0, 7), slice(1, 12))


@pytest.mark.parametrize("r", [1, 3])
def test_dilating_within_the_window_is_dilating_the_whole_grid(r):
    rng = np.random.default_rng(r)
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    disk = xx**2 + yy**2 <= r * r
    for _ in range(20):
        m = np.zeros((60, 70), dtype=bool)
        n = rng.integers(0, 6)
        m[rng.integers(0, 60, n), rng.integers(0, 70, n)] = True  # the borders included
        want = ndimage.binary_dilation(m, disk)
        np.testing.assert_array_equal(_dilated(m, disk), want)
        # the cells in groups that lie apart, each dilated in its own window
        xy = np.argwhere(m)[:, ::-1]
        groups = [xy[xy[:, 0] < 35], xy[xy[:, 0] >= 35]]
        np.testing.assert_array_equal(_dilated(m, disk, groups), want)


def _regions_whole_grid(after, before):
    """The region updates as first written: grow and label the whole grid."""
    lab, _ = ndimage.label(ndimage.binary_dilation(after != before, iterations=2))
    return [(after[sl].copy(), sl[1].start, sl[0].start)
            for sl in ndimage.find_objects(lab) if sl is not None]


def test_changed_regions_are_those_of_the_whole_grid():
    rng = np.random.default_rng(7)
    for _ in range(30):
        before = rng.choice(np.array([0, 100, -1], dtype=np.int8), size=(50, 64))
        after = before.copy()
        for _ in range(rng.integers(0, 5)):  # a few changed patches, some at the border
            y, x = rng.integers(0, 50), rng.integers(0, 64)
            after[y:y + rng.integers(1, 6), x:x + rng.integers(1, 6)] = 100
        got, want = _changed_regions(after, before), _regions_whole_grid(after, before)
        assert len(got) == len(want)
        for (c1, x1, y1), (c2, x2, y2) in zip(got, want, strict=True):
            assert (x1, y1) == (x2, y2)
            np.testing.assert_array_equal(c1, c2)
