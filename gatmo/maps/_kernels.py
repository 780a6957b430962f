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


# ------------------------------------------------------------------ distance-field ray marching
@njit(cache=True, inline="always")
def _march_one(sd, gx, gy, dx, dy, max_t, jump_min):
    """Exact range, in cells, from grid point (gx, gy) along unit (dx, dy) to the entry of the
    first blocking cell; ``max_t`` when the ray leaves the grid or reaches ``max_t`` first.

    ``sd`` (H, W) float32 is a march table (:func:`gatmo.maps.raycast.march_table`): < 0 on a
    blocking cell, else a distance [cells] that any ray starting anywhere in that cell (boundary
    included) travels without touching a blocking cell. Where it is >= ``jump_min`` the ray
    jumps by it (sphere tracing on the distance transform); elsewhere it walks cell by cell
    (Amanatides-Woo), so the hit is found by the cell walk and is exact, as :func:`_cast_one`.
    """
    h, w = sd.shape
    ix = int(np.floor(gx))
    iy = int(np.floor(gy))
    if ix < 0 or iy < 0 or ix >= w or iy >= h:
        return max_t
    v = sd[iy, ix]
    if v < 0:
        return 0.0
    big = 1e30
    step_x = 1 if dx > 0 else -1
    step_y = 1 if dy > 0 else -1
    inv_x = 1.0 / dx if dx != 0.0 else 0.0
    inv_y = 1.0 / dy if dy != 0.0 else 0.0
    t_dx = abs(inv_x) if dx != 0.0 else big
    t_dy = abs(inv_y) if dy != 0.0 else big
    t = 0.0
    px = gx
    py = gy
    while True:
        if v >= jump_min:
            t += v
            if t >= max_t:
                return max_t
            px = gx + t * dx
            py = gy + t * dy
            ix = int(np.floor(px))
            iy = int(np.floor(py))
            if ix < 0 or iy < 0 or ix >= w or iy >= h:
                return max_t
            v = sd[iy, ix]
            continue
        # cell walk from (px, py) at distance t inside cell (ix, iy)
        t_max_x = t + ((ix + 1 if dx > 0 else ix) - px) * inv_x if dx != 0.0 else big
        t_max_y = t + ((iy + 1 if dy > 0 else iy) - py) * inv_y if dy != 0.0 else big
        while True:
            if t_max_x < t_max_y:
                t = t_max_x
                ix += step_x
                t_max_x += t_dx
            else:
                t = t_max_y
                iy += step_y
                t_max_y += t_dy
            if t >= max_t:
                return max_t
            if ix < 0 or iy < 0 or ix >= w or iy >= h:
                return max_t
            v = sd[iy, ix]
            if v < 0:
                return t
            if v >= jump_min:
                px = gx + t * dx
                py = gy + t * dy
                break


@njit(cache=True, parallel=True)
def cast_rays_march_kernel(sd, res, ox, oy, poses, angles, max_range, jump_min):
    """(P, B) ranges [m] by :func:`_march_one`, same as :func:`cast_rays_many_kernel`."""
    p = poses.shape[0]
    b = angles.shape[0]
    out = np.empty((p, b))
    inv = 1.0 / res
    max_t = max_range * inv
    for i in prange(p):
        gx = (poses[i, 0] - ox) * inv
        gy = (poses[i, 1] - oy) * inv
        for j in range(b):
            a = poses[i, 2] + angles[j]
            t = _march_one(sd, gx, gy, np.cos(a), np.sin(a), max_t, jump_min)
            out[i, j] = max_range if t >= max_t else t * res
    return out


# ------------------------------------------------------------------ range lookup table
@njit(cache=True, parallel=True)
def range_table_build_kernel(sd, index, rows_ix, rows_iy, bins, max_t, scale_cells, jump_min):
    """(R, bins) uint16 ranges from the centre of each listed cell at headings
    2 pi (k + 1/2) / bins (half a bin off the axes and diagonals, where a ray from a centre runs
    through cell corners), in units of ``scale_cells`` cells, by :func:`_march_one`; 65535 = no
    hit within max_t."""
    r = rows_ix.shape[0]
    out = np.empty((r, bins), dtype=np.uint16)
    ca = np.empty(bins)
    sa = np.empty(bins)
    for k in range(bins):
        a = 2.0 * np.pi * (k + 0.5) / bins
        ca[k] = np.cos(a)
        sa[k] = np.sin(a)
    for q in prange(r):
        gx = rows_ix[q] + 0.5
        gy = rows_iy[q] + 0.5
        for k in range(bins):
            t = _march_one(sd, gx, gy, ca[k], sa[k], max_t, jump_min)
            if t >= max_t:
                out[q, k] = 65535
            else:
                out[q, k] = min(int(t / scale_cells + 0.5), 65534)
    return out


@njit(cache=True, inline="always")
def _lut_one(index, ranges, scale_cells, gx, gy, u, dx, dy, max_t):
    """Approximate range [cells] from grid point (gx, gy) along the heading of bin coordinate
    ``u`` = heading * bins / (2 pi) (any real; cheapest in [-bins, 2 bins)) with unit vector
    (dx, dy): the table's ranges from the cell centre at the two nearest heading bins,
    interpolated linearly (the nearest bin alone where they differ by more than 4 cells),
    moved by the point's offset from the centre along the ray."""
    h, w = index.shape
    ix = int(np.floor(gx))
    iy = int(np.floor(gy))
    if ix < 0 or iy < 0 or ix >= w or iy >= h:
        return max_t
    row = index[iy, ix]
    if row < 0:
        return 0.0
    bins = ranges.shape[1]
    u -= 0.5  # bin k holds heading 2 pi (k + 1/2) / bins
    fl = np.floor(u)
    f = u - fl
    k0 = int(fl)
    if k0 < 0:
        k0 += bins
    elif k0 >= bins:
        k0 -= bins
    if k0 < 0 or k0 >= bins:
        k0 %= bins
    k1 = k0 + 1 if k0 + 1 < bins else 0
    r0 = ranges[row, k0]
    r1 = ranges[row, k1]
    if r0 == 65535 or r1 == 65535 or abs(float(r0) - float(r1)) * scale_cells > 4.0:
        # a bin sees nothing within range, or the two bins see different obstacles (more than
        # 4 cells apart): interpolating would invent a range neither sees; the nearest decides
        rn = r0 if f < 0.5 else r1
        if rn == 65535:
            return max_t
        t = rn * scale_cells
    else:
        t = ((1.0 - f) * r0 + f * r1) * scale_cells
    t -= (gx - ix - 0.5) * dx + (gy - iy - 0.5) * dy
    if t < 0.0:
        return 0.0
    return t if t < max_t else max_t


@njit(cache=True, parallel=True)
def cast_rays_lut_kernel(index, ranges, scale_cells, res, ox, oy, poses, beam_bins, ca, sa,
                         max_range):
    """(P, B) approximate ranges [m] by :func:`_lut_one` for beams at angles a_j given as
    ``beam_bins`` = a_j * bins / (2 pi) with a_j in [-pi, pi), ``ca`` = cos a_j, ``sa`` = sin a_j
    (the beam model's arithmetic, so both give the same ranges)."""
    p = poses.shape[0]
    b = beam_bins.shape[0]
    bins = ranges.shape[1]
    out = np.empty((p, b))
    inv = 1.0 / res
    max_t = max_range * inv
    for i in prange(p):
        gx = (poses[i, 0] - ox) * inv
        gy = (poses[i, 1] - oy) * inv
        lc = np.cos(poses[i, 2])
        ls = np.sin(poses[i, 2])
        u0 = poses[i, 2] * (bins / (2.0 * np.pi))
        u0 -= bins * np.floor(u0 / bins)
        for j in range(b):
            t = _lut_one(index, ranges, scale_cells, gx, gy, u0 + beam_bins[j],
                         lc * ca[j] - ls * sa[j], ls * ca[j] + lc * sa[j], max_t)
            out[i, j] = max_range if t >= max_t else t * res
    return out


@njit(cache=True, parallel=True)
def range_table_update_kernel(sd, ranges, rows_ix, rows_iy, live, max_t, scale_cells,
                              jump_min, x0, y0, x1, y1):
    """Recast, in place, every ray of ``ranges`` (rows with ``live``) whose old segment (centre to
    its stored range) touches the box [x0, x1] x [y0, y1] (grid units, dilated by 0.01): the
    only rays a change of the cells inside the box can alter. Returns the number recast."""
    r = ranges.shape[0]
    bins = ranges.shape[1]
    eps = 0.01
    bx0 = x0 - eps
    by0 = y0 - eps
    bx1 = x1 + eps
    by1 = y1 + eps
    two_pi = 2.0 * np.pi
    count = np.zeros(r, dtype=np.int64)
    for q in prange(r):
        if not live[q]:
            continue
        gx = rows_ix[q] + 0.5
        gy = rows_iy[q] + 0.5
        inside = bx0 <= gx <= bx1 and by0 <= gy <= by1
        # nearest distance from the centre to the box: shorter rays cannot reach it
        ddx = max(bx0 - gx, 0.0, gx - bx1)
        ddy = max(by0 - gy, 0.0, gy - by1)
        near = np.sqrt(ddx * ddx + ddy * ddy)
        if near >= max_t:
            continue
        k_lo = 0
        k_hi = bins - 1
        if not inside:
            # headings of the box corners around the heading of its centre: a span < pi
            ac = np.arctan2(0.5 * (by0 + by1) - gy, 0.5 * (bx0 + bx1) - gx)
            lo = 0.0
            hi = 0.0
            for cx, cy in ((bx0, by0), (bx1, by0), (bx0, by1), (bx1, by1)):
                d = np.arctan2(cy - gy, cx - gx) - ac
                d = (d + np.pi) % two_pi - np.pi
                lo = min(lo, d)
                hi = max(hi, d)
            k_lo = int(np.floor((ac + lo) * bins / two_pi - 0.5)) - 1
            k_hi = int(np.ceil((ac + hi) * bins / two_pi - 0.5)) + 1
            if k_hi - k_lo >= bins:
                k_lo = 0
                k_hi = bins - 1
        for kk in range(k_lo, k_hi + 1):
            k = kk % bins
            old = ranges[q, k]
            t_old = max_t if old == 65535 else old * scale_cells
            if not inside:
                if t_old + eps < near:
                    continue
                a = two_pi * (k + 0.5) / bins
                dx = np.cos(a)
                dy = np.sin(a)
                tmin = 0.0
                tmax = t_old + eps
                if dx != 0.0:
                    t1 = (bx0 - gx) / dx
                    t2 = (bx1 - gx) / dx
                    tmin = max(tmin, min(t1, t2))
                    tmax = min(tmax, max(t1, t2))
                elif gx < bx0 or gx > bx1:
                    continue
                if dy != 0.0:
                    t1 = (by0 - gy) / dy
                    t2 = (by1 - gy) / dy
                    tmin = max(tmin, min(t1, t2))
                    tmax = min(tmax, max(t1, t2))
                elif gy < by0 or gy > by1:
                    continue
                if tmin > tmax:
                    continue
            else:
                a = two_pi * (k + 0.5) / bins
                dx = np.cos(a)
                dy = np.sin(a)
            t = _march_one(sd, gx, gy, dx, dy, max_t, jump_min)
            if t >= max_t:
                ranges[q, k] = 65535
            else:
                ranges[q, k] = min(int(t / scale_cells + 0.5), 65534)
            count[q] += 1
    return count.sum()
