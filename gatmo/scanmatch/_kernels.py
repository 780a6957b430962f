"""numba kernels for scan matching. The plain-numpy reference is
:func:`gatmo.scanmatch.correlative.correlative_scores_reference`; tests check that both agree."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True)
def correlative_scores_kernel(field, cells_x, cells_y, offsets_x, offsets_y):
    """Mean of ``field`` (H, W) over points shifted by every offset, for every rotation.

    ``cells_x``, ``cells_y`` (A, N) int: each rotation's points as cell indices;
    ``offsets_x`` (NX,), ``offsets_y`` (NY,) int: shifts in cells. Points outside the field
    count 0. Returns (A, NY, NX) scores in [0, max(field)].
    """
    h, w = field.shape
    n_a, n = cells_x.shape
    nx = offsets_x.shape[0]
    ny = offsets_y.shape[0]
    out = np.zeros((n_a, ny, nx))
    for a in prange(n_a):
        for k in range(n):
            cx = cells_x[a, k]
            cy = cells_y[a, k]
            for j in range(ny):
                y = cy + offsets_y[j]
                if y < 0 or y >= h:
                    continue
                for i in range(nx):
                    x = cx + offsets_x[i]
                    if 0 <= x < w:
                        out[a, j, i] += field[y, x]
        if n > 0:
            for j in range(ny):
                for i in range(nx):
                    out[a, j, i] /= n
    return out


@njit(cache=True, parallel=True)
def block_scores_kernel(field, cells_x, cells_y, block_a, block_x0, block_y0, k, n_max):
    """Scores of ``k`` x ``k`` blocks of offsets: block m uses rotation ``block_a[m]`` and
    offsets ``block_x0[m] + i``, ``block_y0[m] + j`` (cells), i, j < k; offsets beyond
    +-``n_max`` score -1. Returns (M, k, k) [j, i]."""
    h, w = field.shape
    n = cells_x.shape[1]
    m_all = block_a.shape[0]
    out = np.zeros((m_all, k, k))
    for m in prange(m_all):
        a = block_a[m]
        for p in range(n):
            cx = cells_x[a, p] + block_x0[m]
            cy = cells_y[a, p] + block_y0[m]
            for j in range(k):
                y = cy + j
                if y < 0 or y >= h:
                    continue
                for i in range(k):
                    x = cx + i
                    if 0 <= x < w:
                        out[m, j, i] += field[y, x]
        for j in range(k):
            for i in range(k):
                if n > 0:
                    out[m, j, i] /= n
                if block_x0[m] + i > n_max or block_y0[m] + j > n_max:
                    out[m, j, i] = -1.0
    return out
