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
