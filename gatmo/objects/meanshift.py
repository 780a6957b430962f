"""Mean shift clustering of 2D points (flat kernel), vectorised."""

from __future__ import annotations

import numpy as np


def mean_shift(points_xy: np.ndarray, bandwidth_m: float, max_iter: int = 30,
               tol_m: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Cluster points (N, 2): returns (centres (C, 2), labels (N,)).

    Every point climbs to the mean of the points within ``bandwidth_m`` of its current estimate
    until it stops moving; modes closer than half the bandwidth are merged.
    """
    pts = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    modes = pts.copy()
    bw2 = bandwidth_m**2
    for _ in range(max_iter):
        d2 = ((modes[:, None, :] - pts[None, :, :]) ** 2).sum(-1)
        w = d2 <= bw2
        new = (w[..., None] * pts[None]).sum(1) / np.maximum(w.sum(1), 1)[:, None]
        shift = np.max(np.hypot(*(new - modes).T))
        modes = new
        if shift < tol_m:
            break
    centres: list[np.ndarray] = []
    labels = np.empty(len(pts), dtype=np.int64)
    for i, m in enumerate(modes):
        for k, c in enumerate(centres):
            if np.hypot(*(m - c)) < bandwidth_m / 2:
                labels[i] = k
                break
        else:
            centres.append(m)
            labels[i] = len(centres) - 1
    return np.array(centres), labels
