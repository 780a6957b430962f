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


def soft_distance_field(occupied: np.ndarray, soft: np.ndarray, resolution_m: float,
                        max_dist_m: float, soft_factor: float = 1.0,
                        soft_offset_m: float = 0.0) -> np.ndarray:
    """(H, W) metres, clipped: the distance to the nearest hard occupied cell, or
    ``sqrt((d / soft_factor)**2 + soft_offset_m**2)`` with ``d`` the distance to the nearest
    soft one (``occupied & soft``), whichever is smaller. A gaussian of sigma on this distance
    is, around the soft cells, a gaussian ``soft_factor`` times wider and
    ``exp(-soft_offset_m**2 / (2 sigma**2))`` times lower."""
    soft = occupied & soft
    if (soft_factor == 1.0 and soft_offset_m == 0.0) or not soft.any():
        return distance_field(occupied, resolution_m, max_dist_m)
    d = distance_field(occupied & ~soft, resolution_m, max_dist_m)
    d_soft = distance_field(soft, resolution_m, max_dist_m * soft_factor) / soft_factor
    return np.minimum(d, np.minimum(np.hypot(d_soft, soft_offset_m), max_dist_m))


class LikelihoodField:
    """Distance field of an :class:`OccupancyGrid` (AMCL's ``map_update_cspace``).

    Beyond AMCL: occupied cells may be marked *soft* (furniture that may have moved since the
    map was made); distances to them are divided by ``soft_factor`` (>= 1) and lengthened by
    ``soft_offset_m`` (:func:`soft_distance_field`), so the sensor model's gaussian around
    them is wider and lower, and a piece shifted by a few centimetres pulls the particles
    onto its old place less than a wall does.

    Attributes:
        grid: the map (its cells are changed in place by :meth:`update_region`).
        max_dist_m: clip distance (AMCL's ``laser_likelihood_max_dist``).
        soft_factor: how much wider the gaussian is around soft cells (1: as around any).
        soft_offset_m: the distance a return right on a soft cell is scored at (0: none).
        soft: (H, W) bool, the occupied cells that are soft (others are ignored).
        dist_m: (H, W) float64 distances [m].
    """

    def __init__(self, grid: OccupancyGrid, max_dist_m: float, soft_factor: float = 1.0,
                 soft: np.ndarray | None = None, soft_offset_m: float = 0.0) -> None:
        if soft_factor < 1.0 or soft_offset_m < 0.0:
            raise ValueError(f"soft_factor must be >= 1 and soft_offset_m >= 0, got "
                             f"{soft_factor} and {soft_offset_m}")
        self.max_dist_m = float(max_dist_m)
        self.soft_factor = float(soft_factor)
        self.soft_offset_m = float(soft_offset_m)
        self.version = 0  # bumped on every change, so derived tables know when to refresh
        self.changed_windows: list[tuple[int, int, int, int]] = []
        self.set_grid(grid, soft)

    def _distances(self, cells: np.ndarray, soft: np.ndarray, resolution_m: float) -> np.ndarray:
        return soft_distance_field(cells == OCCUPIED, soft, resolution_m, self.max_dist_m,
                                   self.soft_factor, self.soft_offset_m)

    def set_grid(self, grid: OccupancyGrid, soft: np.ndarray | None = None) -> None:
        """Replace the map (and its soft cells, (H, W) bool; none if None) and recompute
        the whole field."""
        self.grid = grid
        self.soft = (np.zeros(grid.cells.shape, dtype=bool) if soft is None
                     else np.asarray(soft, dtype=bool).copy())
        if self.soft.shape != grid.cells.shape:
            raise ValueError(f"soft mask {self.soft.shape} does not match the map "
                             f"{grid.cells.shape}")
        self.dist_m = self._distances(grid.cells, self.soft, grid.resolution_m)
        self.version += 1
        self.changed_windows = [(0, 0, grid.width, grid.height)]

    def distance_at(self, points_xy: np.ndarray) -> np.ndarray:
        """Distances (N,) [m] at world points (N, 2); off-map points get ``max_dist_m``."""
        c = self.grid.world_to_cell(points_xy)
        ok = self.grid.in_bounds(c)
        out = np.full(len(c), self.max_dist_m)
        out[ok] = self.dist_m[c[ok, 1], c[ok, 0]]
        return out

    def update_region(self, cells_new: np.ndarray, ix0: int, iy0: int,
                      soft_new: np.ndarray | None = None):
        """Write ``cells_new`` (h, w) at cell (ix0, iy0) (and ``soft_new`` (h, w) bool into the
        soft mask, if given) and recompute only what can change.

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
        if soft_new is not None:
            self.soft[y0:y1, x0:x1] = np.asarray(soft_new, dtype=bool)[
                y0 - iy0 : y1 - iy0, x0 - ix0 : x1 - ix0]
        # a soft cell (written now or before) reaches soft_factor times as far
        m = int(np.ceil(self.max_dist_m * self.soft_factor / g.resolution_m)) + 1
        ax0, ay0 = max(x0 - m, 0), max(y0 - m, 0)
        ax1, ay1 = min(x1 + m, g.width), min(y1 + m, g.height)
        bx0, by0 = max(x0 - 2 * m, 0), max(y0 - 2 * m, 0)
        bx1, by1 = min(x1 + 2 * m, g.width), min(y1 + 2 * m, g.height)
        d = self._distances(g.cells[by0:by1, bx0:bx1], self.soft[by0:by1, bx0:bx1],
                            g.resolution_m)
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
