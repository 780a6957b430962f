"""numba kernels for grid ray casting (Amanatides-Woo traversal). Plain-numpy references live in
:mod:`gatmo.maps.raycast`; tests check that both agree."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _dda_init(gx, gy, ix, iy, dx, dy, res):
    """Amanatides-Woo set-up from grid coordinates (gx, gy) in cell (ix, iy) along unit
    (dx, dy): steps, distances [m] to the first x and y cell boundaries, and per cell."""
    big = 1e30
    step_x = 1 if dx > 0 else -1
    step_y = 1 if dy > 0 else -1
    if dx != 0.0:
        t_max_x = ((ix + 1 if dx > 0 else ix) - gx) / dx * res
        t_dx = res / abs(dx)
    else:
        t_max_x = big
        t_dx = big
    if dy != 0.0:
        t_max_y = ((iy + 1 if dy > 0 else iy) - gy) / dy * res
        t_dy = res / abs(dy)
    else:
        t_max_y = big
        t_dy = big
    return step_x, step_y, t_max_x, t_max_y, t_dx, t_dy


@njit(cache=True, inline="always")
def _dda_step(ix, iy, t_max_x, t_max_y, step_x, step_y, t_dx, t_dy):
    """Cross into the next cell: (distance at entry, ix, iy, next t_max_x, next t_max_y)."""
    if t_max_x < t_max_y:
        return t_max_x, ix + step_x, iy, t_max_x + t_dx, t_max_y
    return t_max_y, ix, iy + step_y, t_max_x, t_max_y + t_dy


@njit(cache=True, inline="always")
def _cast_one(cells, res, ox, oy, x0, y0, ang, max_range, stop_unknown):
    """Range from world (x0, y0) along ``ang`` to the entry of the first blocking cell."""
    h, w = cells.shape
    dx = np.cos(ang)
    dy = np.sin(ang)
    gx = (x0 - ox) / res
    gy = (y0 - oy) / res
    ix = int(np.floor(gx))
    iy = int(np.floor(gy))
    if ix < 0 or iy < 0 or ix >= w or iy >= h:
        return max_range
    v = cells[iy, ix]
    if v == 100 or (stop_unknown and v == -1):
        return 0.0
    step_x, step_y, t_max_x, t_max_y, t_dx, t_dy = _dda_init(gx, gy, ix, iy, dx, dy, res)
    while True:
        t, ix, iy, t_max_x, t_max_y = _dda_step(ix, iy, t_max_x, t_max_y, step_x, step_y,
                                                t_dx, t_dy)
        if t >= max_range:
            return max_range
        if ix < 0 or iy < 0 or ix >= w or iy >= h:
            return max_range
        v = cells[iy, ix]
        if v == 100 or (stop_unknown and v == -1):
            return t


@njit(cache=True, parallel=True)
def cast_rays_many_kernel(cells, res, ox, oy, poses, angles, max_range, stop_unknown):
    """(P, B) ranges for P sensor poses (x, y, theta) and B beam angles."""
    p = poses.shape[0]
    b = angles.shape[0]
    out = np.empty((p, b))
    for i in prange(p):
        for j in range(b):
            out[i, j] = _cast_one(
                cells, res, ox, oy, poses[i, 0], poses[i, 1], poses[i, 2] + angles[j], max_range,
                stop_unknown,
            )
    return out


@njit(cache=True)
def traverse_rays_kernel(cells_shape_h, cells_shape_w, res, ox, oy, x0, y0, ends, exclude_end_m):
    """Cells crossed by rays from (x0, y0) to each endpoint, endpoint cell excluded.

    Returns (cells (K, 2) as ix, iy; ray index (K,)). Only in-grid cells.
    """
    h, w = cells_shape_h, cells_shape_w
    n = ends.shape[0]
    cap = 64
    out = np.empty((cap, 2), dtype=np.int64)
    idx = np.empty(cap, dtype=np.int64)
    k = 0
    gx0 = (x0 - ox) / res
    gy0 = (y0 - oy) / res
    for r in range(n):
        ex = ends[r, 0]
        ey = ends[r, 1]
        ddx = ex - x0
        ddy = ey - y0
        length = np.sqrt(ddx * ddx + ddy * ddy)
        if length <= 0.0:
            continue
        dx = ddx / length
        dy = ddy / length
        ix = int(np.floor(gx0))
        iy = int(np.floor(gy0))
        eix = int(np.floor((ex - ox) / res))
        eiy = int(np.floor((ey - oy) / res))
        step_x, step_y, t_max_x, t_max_y, t_dx, t_dy = _dda_init(gx0, gy0, ix, iy, dx, dy, res)
        t = 0.0
        while True:
            if ix == eix and iy == eiy:
                break
            if t > length:
                break
            # the cell centre must lie farther than exclude_end_m from the endpoint
            cxw = ox + (ix + 0.5) * res
            cyw = oy + (iy + 0.5) * res
            de = np.sqrt((cxw - ex) ** 2 + (cyw - ey) ** 2)
            if ix >= 0 and iy >= 0 and ix < w and iy < h and de > exclude_end_m:
                if k >= cap:
                    cap *= 2
                    out2 = np.empty((cap, 2), dtype=np.int64)
                    idx2 = np.empty(cap, dtype=np.int64)
                    out2[:k] = out[:k]
                    idx2[:k] = idx[:k]
                    out = out2
                    idx = idx2
                out[k, 0] = ix
                out[k, 1] = iy
                idx[k] = r
                k += 1
            t, ix, iy, t_max_x, t_max_y = _dda_step(ix, iy, t_max_x, t_max_y, step_x, step_y,
                                                    t_dx, t_dy)
    return out[:k].copy(), idx[:k].copy()
