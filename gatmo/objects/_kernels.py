"""numba kernels for object matching, beside plain numpy references (tests check they agree)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True, fastmath=False)
def score_poses_kernel(val, lo_x, lo_y, res, pts, thetas, offs_x, offs_y):  # pragma: no cover
    """Mean field value of ``pts`` (P, 2) (map frame, already centred on the points' centroid)
    seen in the object frame for every rotation ``thetas`` (R,) and translation (offs_x[i],
    offs_y[j]) of the object's origin: q = R(theta)^T (p - t). Returns (R, I, J) float64."""
    n_r = thetas.shape[0]
    n_i = offs_x.shape[0]
    n_j = offs_y.shape[0]
    n_p = pts.shape[0]
    h, w = val.shape
    out = np.zeros((n_r, n_i, n_j))
    for r in prange(n_r):
        c = np.cos(thetas[r])
        s = np.sin(thetas[r])
        for i in range(n_i):
            for j in range(n_j):
                acc = 0.0
                for k in range(n_p):
                    x = pts[k, 0] - offs_x[i]
                    y = pts[k, 1] - offs_y[j]
                    qx = c * x + s * y
                    qy = -s * x + c * y
                    ix = int(np.floor((qx - lo_x) / res))
                    iy = int(np.floor((qy - lo_y) / res))
                    if ix >= 0 and ix < w and iy >= 0 and iy < h:
                        acc += val[iy, ix]
                out[r, i, j] = acc / max(n_p, 1)
    return out


def score_poses_reference(val, lo_x, lo_y, res, pts, thetas, offs_x, offs_y) -> np.ndarray:
    """numpy reference of :func:`score_poses_kernel`."""
    out = np.zeros((len(thetas), len(offs_x), len(offs_y)))
    h, w = val.shape
    tx, ty = np.meshgrid(offs_x, offs_y, indexing="ij")
    for r, th in enumerate(thetas):
        c, s = np.cos(th), np.sin(th)
        x = pts[None, None, :, 0] - tx[..., None]
        y = pts[None, None, :, 1] - ty[..., None]
        qx = c * x + s * y
        qy = -s * x + c * y
        ix = np.floor((qx - lo_x) / res).astype(np.int64)
        iy = np.floor((qy - lo_y) / res).astype(np.int64)
        ok = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
        v = np.where(ok, val[np.clip(iy, 0, h - 1), np.clip(ix, 0, w - 1)], 0.0)
        out[r] = v.sum(-1) / max(len(pts), 1)
    return out
