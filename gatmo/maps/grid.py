"""Occupancy grids in the ROS ``nav_msgs/OccupancyGrid`` convention.

``cells[iy, ix]``: row ``iy`` grows with world y, column ``ix`` with world x; cell (0, 0) has its
lower left corner at the origin. Values: ``FREE = 0``, ``OCCUPIED = 100``, ``UNKNOWN = -1`` (int8).
The origin's yaw must be 0: map_server writes it but AMCL ignores it, so a rotated origin would be
silently misread; gatmo refuses it instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gatmo.errors import MapError

FREE = np.int8(0)
OCCUPIED = np.int8(100)
UNKNOWN = np.int8(-1)


@dataclass
class OccupancyGrid:
    """A 2D occupancy grid.

    Attributes:
        cells: (H, W) int8 with values FREE / OCCUPIED / UNKNOWN.
        resolution_m: cell side length in metres.
        origin_xytheta: world pose (x_m, y_m, yaw_rad) of the lower-left corner of cell (0, 0);
            yaw must be 0.
    """

    cells: np.ndarray
    resolution_m: float
    origin_xytheta: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        self.cells = np.ascontiguousarray(self.cells, dtype=np.int8)
        if self.cells.ndim != 2 or self.cells.size == 0:
            raise MapError(f"grid must be a non-empty 2D array, got shape {self.cells.shape}")
        if not np.isfinite(self.resolution_m) or self.resolution_m <= 0:
            raise MapError(f"resolution must be > 0, got {self.resolution_m}", field="resolution")
        ox, oy, oyaw = (float(v) for v in self.origin_xytheta)
        if not (np.isfinite(ox) and np.isfinite(oy) and np.isfinite(oyaw)):
            raise MapError("origin must be finite", field="origin")
        if abs(oyaw) > 1e-9:
            raise MapError(
                f"origin yaw {oyaw} rad is not supported (AMCL ignores it); rotate the image",
                field="origin",
            )
        self.resolution_m = float(self.resolution_m)
        self.origin_xytheta = (ox, oy, 0.0)

    # ------------------------------------------------------------------ shape
    @property
    def height(self) -> int:
        return int(self.cells.shape[0])

    @property
    def width(self) -> int:
        return int(self.cells.shape[1])

    @property
    def origin_xy(self) -> np.ndarray:
        return np.array(self.origin_xytheta[:2])

    @property
    def extent_xy(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) in metres."""
        ox, oy = self.origin_xytheta[:2]
        return ox, ox + self.width * self.resolution_m, oy, oy + self.height * self.resolution_m

    def copy(self) -> OccupancyGrid:
        return OccupancyGrid(self.cells.copy(), self.resolution_m, self.origin_xytheta)

    # ------------------------------------------------------------ transforms
    def world_to_cell(self, points_xy: np.ndarray) -> np.ndarray:
        """World points (N, 2) [m] -> integer cells (N, 2) as (ix, iy); may lie outside the grid."""
        p = np.asarray(points_xy, dtype=float)
        return np.floor((p - self.origin_xy) / self.resolution_m).astype(np.int64)

    def cell_to_world(self, cells_ixy: np.ndarray) -> np.ndarray:
        """Cells (N, 2) as (ix, iy) -> world coordinates (N, 2) [m] of the cell centres."""
        c = np.asarray(cells_ixy, dtype=float)
        return (c + 0.5) * self.resolution_m + self.origin_xy

    def in_bounds(self, cells_ixy: np.ndarray) -> np.ndarray:
        """Boolean mask (N,) of cells inside the grid."""
        c = np.asarray(cells_ixy)
        return (
            (c[..., 0] >= 0)
            & (c[..., 0] < self.width)
            & (c[..., 1] >= 0)
            & (c[..., 1] < self.height)
        )

    def value_at(self, points_xy: np.ndarray) -> np.ndarray:
        """Cell values (N,) at world points; UNKNOWN outside the grid."""
        c = self.world_to_cell(points_xy)
        ok = self.in_bounds(c)
        out = np.full(len(c), UNKNOWN, dtype=np.int8)
        out[ok] = self.cells[c[ok, 1], c[ok, 0]]
        return out

    # ------------------------------------------------------------------ masks
    @property
    def occupied(self) -> np.ndarray:
        return self.cells == OCCUPIED

    @property
    def free(self) -> np.ndarray:
        return self.cells == FREE

    @property
    def unknown(self) -> np.ndarray:
        return self.cells == UNKNOWN

    def free_cells_world(self) -> np.ndarray:
        """Centres (N, 2) [m] of all free cells."""
        iy, ix = np.nonzero(self.free)
        return self.cell_to_world(np.stack([ix, iy], axis=1))

    def occupied_cells_world(self) -> np.ndarray:
        """Centres (N, 2) [m] of all occupied cells."""
        iy, ix = np.nonzero(self.occupied)
        return self.cell_to_world(np.stack([ix, iy], axis=1))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, OccupancyGrid):
            return NotImplemented
        return (
            self.resolution_m == other.resolution_m
            and self.origin_xytheta == other.origin_xytheta
            and np.array_equal(self.cells, other.cells)
        )


def add_counts(counts: np.ndarray, iy: np.ndarray, ix: np.ndarray) -> None:
    """``counts[iy[k], ix[k]] += 1`` for every k, repeated cells counted as often as they
    appear: what ``np.add.at(counts, (iy, ix), 1)`` does, for an integer ``counts`` (H, W),
    exactly, many times faster (a ``bincount`` over the cells' bounding box: rays from one scan
    cover a small part of a large map). Indices must be in bounds."""
    if len(iy) == 0:
        return
    y0, x0 = int(iy.min()), int(ix.min())
    h, w = int(iy.max()) - y0 + 1, int(ix.max()) - x0 + 1
    box = np.bincount((iy - y0) * w + (ix - x0), minlength=h * w).reshape(h, w)
    counts[y0:y0 + h, x0:x0 + w] += box.astype(counts.dtype, copy=False)
