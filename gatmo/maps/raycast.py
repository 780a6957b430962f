"""Ray casting on occupancy grids: ranges to the first blocking cell, and the cells a ray crosses.

Kernels are numba (``_kernels.py``); the ``_reference`` functions here are plain numpy (fine ray
marching) and exist so tests can check the kernels.
"""

from __future__ import annotations

import numpy as np

from gatmo.maps.grid import OCCUPIED, UNKNOWN, OccupancyGrid


def cast_rays_many(
    grid: OccupancyGrid,
    poses_xytheta: np.ndarray,
    angles_rad: np.ndarray,
    max_range_m: float,
    *,
    stop_at_unknown: bool = True,
) -> np.ndarray:
    """Ranges (P, B) [m] from P sensor poses (map frame) along B beams (sensor frame angles).

    A ray stops at the first OCCUPIED cell (and UNKNOWN cell when ``stop_at_unknown``, as AMCL's
    ``map_calc_range``); the range is the distance to that cell's boundary. Rays leaving the grid
    or longer than ``max_range_m`` return ``max_range_m``; a start in a blocking cell returns 0.
    """
    from gatmo.maps._kernels import cast_rays_many_kernel

    poses = np.ascontiguousarray(np.atleast_2d(poses_xytheta), dtype=np.float64)
    angles = np.ascontiguousarray(angles_rad, dtype=np.float64)
    ox, oy = grid.origin_xytheta[:2]
    return cast_rays_many_kernel(
        grid.cells, grid.resolution_m, ox, oy, poses, angles, float(max_range_m),
        bool(stop_at_unknown),
    )


def cast_rays(grid, pose_xytheta, angles_rad, max_range_m, *, stop_at_unknown=True) -> np.ndarray:
    """Ranges (B,) [m] from one sensor pose; see :func:`cast_rays_many`."""
    return cast_rays_many(
        grid, np.asarray(pose_xytheta)[None, :], angles_rad, max_range_m,
        stop_at_unknown=stop_at_unknown,
    )[0]


def traverse_rays(
    grid: OccupancyGrid,
    origin_xy: np.ndarray,
    endpoints_xy: np.ndarray,
    *,
    exclude_end_m: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Cells crossed by rays from ``origin_xy`` (2,) to ``endpoints_xy`` (B, 2), map frame [m].

    Returns ``(cells_ixy (K, 2) int64, ray_index (K,) int64)``: every in-grid cell each ray passes
    through before its endpoint, excluding the endpoint's own cell and any cell whose centre lies
    within ``exclude_end_m`` of the endpoint (a return *on* an object is not a ray *through* it).
    """
    from gatmo.maps._kernels import traverse_rays_kernel

    ends = np.ascontiguousarray(np.atleast_2d(endpoints_xy), dtype=np.float64).reshape(-1, 2)
    ox, oy = grid.origin_xytheta[:2]
    return traverse_rays_kernel(
        grid.height, grid.width, grid.resolution_m, ox, oy, float(origin_xy[0]),
        float(origin_xy[1]), ends, float(exclude_end_m),
    )


def ray_cells(grid: OccupancyGrid, start_xy, end_xy) -> np.ndarray:
    """Cells (K, 2) a segment crosses in order, both end cells included, clipped to the grid."""
    cells, _ = traverse_rays(grid, np.asarray(start_xy, float), np.asarray(end_xy, float)[None])
    end = grid.world_to_cell(np.asarray(end_xy, float)[None])
    if grid.in_bounds(end)[0]:
        cells = np.concatenate([cells, end]) if len(cells) else end
    return cells


# ------------------------------------------------------------------ distance-field ray marching
MARCH_MARGIN_CELLS = np.sqrt(2.0) + 0.01  # a cell's half diagonal at both ends, plus rounding
MARCH_CLIP_CELLS = 64.0  # longest jump; bounds what a region update has to recompute
MARCH_JUMP_MIN_CELLS = 1.0  # below this the march walks cell by cell


def _march_values(cells: np.ndarray, stop_at_unknown: bool, clip_cells: float) -> np.ndarray:
    from gatmo.maps.likelihood import distance_field

    block = cells == OCCUPIED
    if stop_at_unknown:
        block |= cells == UNKNOWN
    d = distance_field(block, 1.0, clip_cells + MARCH_MARGIN_CELLS)
    out = np.maximum(d - MARCH_MARGIN_CELLS, 0.0).astype(np.float32)
    out[block] = -1.0
    return out


def march_table(grid: OccupancyGrid, *, stop_at_unknown: bool = True,
                clip_cells: float = MARCH_CLIP_CELLS) -> np.ndarray:
    """(H, W) float32 table for exact ray marching (:func:`cast_rays_marched`).

    -1 on blocking cells (OCCUPIED, and UNKNOWN when ``stop_at_unknown``); elsewhere a distance
    [cells] that a ray starting anywhere in the cell travels without touching a blocking cell:
    the Euclidean distance between cell centres to the nearest blocking cell minus sqrt(2) (half
    a diagonal at each end) minus 0.01 for rounding, clipped to [0, ``clip_cells``].
    """
    return _march_values(grid.cells, stop_at_unknown, float(clip_cells))


def update_march_table(table: np.ndarray, grid: OccupancyGrid, window, *,
                       stop_at_unknown: bool = True,
                       clip_cells: float = MARCH_CLIP_CELLS) -> None:
    """Refresh ``table`` in place after the cells inside ``window`` = (ix0, iy0, ix1, iy1)
    (exclusive ends) changed; the result equals :func:`march_table` of the new grid."""
    x0, y0, x1, y1 = (int(v) for v in window)
    h, w = table.shape
    m = int(np.ceil(clip_cells + MARCH_MARGIN_CELLS)) + 1
    ax0, ay0, ax1, ay1 = max(x0 - m, 0), max(y0 - m, 0), min(x1 + m, w), min(y1 + m, h)
    bx0, by0 = max(x0 - 2 * m, 0), max(y0 - 2 * m, 0)
    bx1, by1 = min(x1 + 2 * m, w), min(y1 + 2 * m, h)
    if ax1 <= ax0 or ay1 <= ay0:
        return
    sub = _march_values(grid.cells[by0:by1, bx0:bx1], stop_at_unknown, float(clip_cells))
    table[ay0:ay1, ax0:ax1] = sub[ay0 - by0 : ay1 - by0, ax0 - bx0 : ax1 - bx0]


def cast_rays_marched(grid: OccupancyGrid, table: np.ndarray, poses_xytheta: np.ndarray,
                      angles_rad: np.ndarray, max_range_m: float) -> np.ndarray:
    """:func:`cast_rays_many` by jumps on a :func:`march_table` (built with the same
    ``stop_at_unknown``): the same ranges (P, B) [m] up to rounding, much faster in open space.
    """
    from gatmo.maps._kernels import cast_rays_march_kernel

    poses = np.ascontiguousarray(np.atleast_2d(poses_xytheta), dtype=np.float64)
    angles = np.ascontiguousarray(angles_rad, dtype=np.float64)
    ox, oy = grid.origin_xytheta[:2]
    return cast_rays_march_kernel(table, grid.resolution_m, ox, oy, poses, angles,
                                  float(max_range_m), MARCH_JUMP_MIN_CELLS)


class RangeTable:
    """Precomputed ranges for approximate ray casting (range_libc's lookup table, without CDDT's
    compression): for every non-blocking cell and ``bins`` headings 2 pi (k + 1/2) / bins, the
    exact range from the cell centre, uint16 in units of ``scale_m``. A query interpolates the two
    nearest headings linearly (takes the nearest where they differ by more than 4 cells: an
    obstacle edge) and moves the result by the query point's offset from the cell
    centre along the ray; error against exact casting: see tests/maps/test_raycast_likelihood.py.

    Attributes:
        index: (H, W) int32 row of each cell in ``ranges``; -1 on blocking cells.
        ranges: (R, bins) uint16; 65535 = nothing within ``max_range_m``.
        scale_m: metres per unit of ``ranges``.
        max_range_m: the range the table was built for.

    Memory: 2 * bins bytes per free cell (0.7 kB at 360 bins); building casts that many rays.
    :meth:`update` follows a change of the map's cells in a window by recasting only the rays
    that cross it.
    """

    def __init__(self, grid: OccupancyGrid, max_range_m: float, *, bins: int = 360,
                 stop_at_unknown: bool = True, march: np.ndarray | None = None) -> None:
        from gatmo.maps._kernels import range_table_build_kernel

        self.stop_at_unknown = stop_at_unknown
        sd = march if march is not None else march_table(grid, stop_at_unknown=stop_at_unknown)
        free = sd >= 0
        self.index = np.full(sd.shape, -1, dtype=np.int32)
        iy, ix = np.nonzero(free)
        self.index[iy, ix] = np.arange(len(iy), dtype=np.int32)
        self.rows_ix = ix.astype(np.int64)
        self.rows_iy = iy.astype(np.int64)
        self.live = np.ones(len(ix), dtype=np.bool_)
        self.max_range_m = float(max_range_m)
        self.scale_m = self.max_range_m / 65534.0
        self.resolution_m = grid.resolution_m
        self._max_t = self.max_range_m / grid.resolution_m
        self.ranges = range_table_build_kernel(sd, self.index, self.rows_ix, self.rows_iy,
                                               int(bins), self._max_t, self.scale_cells,
                                               MARCH_JUMP_MIN_CELLS)

    def update(self, grid: OccupancyGrid, window, march: np.ndarray) -> int:
        """Follow a change of ``grid.cells`` inside ``window`` = (ix0, iy0, ix1, iy1) (exclusive
        ends); ``march`` is the march table of the changed grid. Afterwards every query answers
        as a table built from scratch would. Returns the number of rays recast.

        Cells that became blocking lose their row (it stays allocated, unused); cells that
        became free get new rows; every other row recasts only its rays whose old segment
        touches the window.
        """
        from gatmo.maps._kernels import range_table_build_kernel, range_table_update_kernel

        x0, y0, x1, y1 = (int(v) for v in window)
        h, w = self.index.shape
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if x1 <= x0 or y1 <= y0:
            return 0
        sub_free = march[y0:y1, x0:x1] >= 0
        sub_idx = self.index[y0:y1, x0:x1]
        gone = ~sub_free & (sub_idx >= 0)
        self.live[sub_idx[gone]] = False
        sub_idx[gone] = -1
        n = range_table_update_kernel(march, self.ranges, self.rows_ix, self.rows_iy, self.live,
                                      self._max_t, self.scale_cells, MARCH_JUMP_MIN_CELLS,
                                      float(x0), float(y0), float(x1), float(y1))
        iy, ix = np.nonzero(sub_free & (sub_idx < 0))
        if len(iy):
            ix = (ix + x0).astype(np.int64)
            iy = (iy + y0).astype(np.int64)
            new = range_table_build_kernel(march, self.index, ix, iy, self.ranges.shape[1],
                                           self._max_t, self.scale_cells, MARCH_JUMP_MIN_CELLS)
            self.index[iy, ix] = np.arange(len(self.rows_ix), len(self.rows_ix) + len(ix),
                                           dtype=np.int32)
            self.rows_ix = np.concatenate([self.rows_ix, ix])
            self.rows_iy = np.concatenate([self.rows_iy, iy])
            self.live = np.concatenate([self.live, np.ones(len(ix), dtype=np.bool_)])
            self.ranges = np.concatenate([self.ranges, new])
            n += new.size
        return int(n)

    @property
    def scale_cells(self) -> float:
        return self.scale_m / self.resolution_m

    def cast(self, grid: OccupancyGrid, poses_xytheta: np.ndarray,
             angles_rad: np.ndarray) -> np.ndarray:
        """Approximate :func:`cast_rays_many` (P, B) [m] with ``max_range_m`` of the table."""
        from gatmo.maps._kernels import cast_rays_lut_kernel

        poses = np.ascontiguousarray(np.atleast_2d(poses_xytheta), dtype=np.float64)
        angles = np.asarray(angles_rad, dtype=np.float64)
        ox, oy = grid.origin_xytheta[:2]
        return cast_rays_lut_kernel(self.index, self.ranges, self.scale_cells,
                                    grid.resolution_m, ox, oy, poses, self.beam_bins(angles),
                                    np.cos(angles), np.sin(angles), self.max_range_m)

    def beam_bins(self, angles_rad: np.ndarray) -> np.ndarray:
        """Beam angles as bin coordinates, wrapped to [-bins/2, bins/2), for the kernels."""
        bins = self.ranges.shape[1]
        a = np.mod(np.asarray(angles_rad, dtype=np.float64) + np.pi, 2 * np.pi) - np.pi
        return np.ascontiguousarray(a * (bins / (2 * np.pi)))


# --------------------------------------------------------------------------- references
def _cast_rays_reference(grid, pose_xytheta, angles_rad, max_range_m, *, stop_at_unknown=True,
                         step_m=None):
    """Fine ray marching in numpy (slow, exact to ``step_m``)."""
    step = step_m or grid.resolution_m / 20.0
    ts = np.arange(0.0, max_range_m + step, step)
    x, y, th = pose_xytheta
    a = th + np.asarray(angles_rad)[:, None]
    px = x + ts[None, :] * np.cos(a)
    py = y + ts[None, :] * np.sin(a)
    c = grid.world_to_cell(np.stack([px.ravel(), py.ravel()], axis=1))
    inside = grid.in_bounds(c)
    vals = np.full(len(c), 0, dtype=np.int8)
    vals[inside] = grid.cells[c[inside, 1], c[inside, 0]]
    block = vals == OCCUPIED
    if stop_at_unknown:
        block |= inside & (vals == UNKNOWN)
    block = block.reshape(px.shape)
    gone = (~inside).reshape(px.shape)
    first_block = np.where(block.any(1), block.argmax(1), len(ts))
    first_gone = np.where(gone.any(1), gone.argmax(1), len(ts))
    out = np.full(len(a), float(max_range_m))
    hit = first_block < first_gone
    out[hit] = ts[first_block[hit]]
    return np.minimum(out, max_range_m)


def _traverse_reference(grid, origin_xy, end_xy, step_m=None):
    """Set of cells (ix, iy) a segment visits by fine marching, endpoint cell excluded."""
    step = step_m or grid.resolution_m / 50.0
    o = np.asarray(origin_xy, float)
    e = np.asarray(end_xy, float)
    n = max(2, int(np.linalg.norm(e - o) / step))
    pts = o + np.linspace(0, 1, n)[:, None] * (e - o)
    c = grid.world_to_cell(pts)
    c = c[grid.in_bounds(c)]
    end = tuple(grid.world_to_cell(e[None])[0])
    return {tuple(x) for x in c.tolist()} - {end}
