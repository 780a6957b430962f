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
