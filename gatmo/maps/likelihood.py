"""The likelihood field: metric distance to the nearest occupied cell, clipped, with exact
region updates for when furniture moves."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import distance_transform_edt

from gatmo.maps.grid import OCCUPIED, OccupancyGrid


def distance_field(occupied: np.ndarray, resolution_m: float, max_dist_m: float) -> np.ndarray:
    """(H, W) metres from each cell centre to the nearest occupied cell centre, clipped."""
    if not occupied.any():
        return np.full(occupied.shape, float(max_dist_m))
    d = distance_transform_edt(~occupied) * resolution_m
    return np.minimum(d, max_dist_m)


class LikelihoodField:
    """Distance field of an :class:`OccupancyGrid` (AMCL's ``map_update_cspace``).

    Attributes:
        grid: the map (its cells are changed in place by :meth:`update_region`).
        max_dist_m: clip distance (AMCL's ``laser_likelihood_max_dist``).
        dist_m: (H, W) float64 distances [m].
    """

    def __init__(self, grid: OccupancyGrid, max_dist_m: float) -> None:
        self.max_dist_m = float(max_dist_m)
        self.version = 0  # bumped on every change, so derived tables know when to refresh
        self.changed_windows: list[tuple[int, int, int, int]] = []
        self.set_grid(grid)

    def set_grid(self, grid: OccupancyGrid) -> None:
        """Replace the map and recompute the whole field."""
        self.grid = grid
        self.dist_m = distance_field(grid.occupied, grid.resolution_m, self.max_dist_m)
        self.version += 1
        self.changed_windows = [(0, 0, grid.width, grid.height)]

    def distance_at(self, points_xy: np.ndarray) -> np.ndarray:
        """Distances (N,) [m] at world points (N, 2); off-map points get ``max_dist_m``."""
        c = self.grid.world_to_cell(points_xy)
        ok = self.grid.in_bounds(c)
        out = np.full(len(c), self.max_dist_m)
        out[ok] = self.dist_m[c[ok, 1], c[ok, 0]]
        return out

    def update_region(self, cells_new: np.ndarray, ix0: int, iy0: int):
        """Write ``cells_new`` (h, w) at cell (ix0, iy0) and recompute only what can change.

        A changed cell alters distances within ``max_dist`` of it; those distances depend on
        occupied cells within ``max_dist`` of *them*, so the EDT runs on the region dilated twice
        and the once-dilated part is copied back. The result equals a full recompute exactly.
        Returns the rewritten window ``(ix0, iy0, ix1, iy1)`` (exclusive ends) or None.
        """
        g = self.grid
        h, w = cells_new.shape
        x0, y0 = max(ix0, 0), max(iy0, 0)
        x1, y1 = min(ix0 + w, g.width), min(iy0 + h, g.height)
        if x1 <= x0 or y1 <= y0:
            return None
        g.cells[y0:y1, x0:x1] = cells_new[y0 - iy0 : y1 - iy0, x0 - ix0 : x1 - ix0]
        m = int(np.ceil(self.max_dist_m / g.resolution_m)) + 1
        ax0, ay0 = max(x0 - m, 0), max(y0 - m, 0)
        ax1, ay1 = min(x1 + m, g.width), min(y1 + m, g.height)
        bx0, by0 = max(x0 - 2 * m, 0), max(y0 - 2 * m, 0)
        bx1, by1 = min(x1 + 2 * m, g.width), min(y1 + 2 * m, g.height)
        occ = g.cells[by0:by1, bx0:bx1] == OCCUPIED
        d = distance_field(occ, g.resolution_m, self.max_dist_m)
        self.dist_m[ay0:ay1, ax0:ax1] = d[ay0 - by0 : ay1 - by0, ax0 - bx0 : ax1 - bx0]
        self.version += 1
        self.changed_windows.append((ax0, ay0, ax1, ay1))
        del self.changed_windows[:-64]
        return ax0, ay0, ax1, ay1

    def apply_grid_diff(self, new_grid: OccupancyGrid):
        """Update to ``new_grid`` (same shape) through one region update of its changed cells."""
        if new_grid.cells.shape != self.grid.cells.shape:
            self.set_grid(new_grid.copy())
            return (0, 0, new_grid.width, new_grid.height)
        diff = new_grid.cells != self.grid.cells
        if not diff.any():
            return None
        iy, ix = np.nonzero(diff)
        y0, y1, x0, x1 = iy.min(), iy.max() + 1, ix.min(), ix.max() + 1
        return self.update_region(new_grid.cells[y0:y1, x0:x1].copy(), int(x0), int(y0))
