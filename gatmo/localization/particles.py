"""Particle-set machinery of AMCL: KLD-sampling bound, systematic resampling, clusters."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from gatmo.geometry import wrap_angle

BIN_XY_M = 0.5
BIN_TH_RAD = np.radians(10.0)


def kld_limit(k: int, err: float, z: float, min_n: int, max_n: int) -> int:
    """Fox 2003: particles needed for k occupied bins, clamped to [min_n, max_n]."""
    if k <= 1:
        return max_n
    b = 2.0 / (9.0 * (k - 1))
    x = 1.0 - b + np.sqrt(b) * z
    n = int(np.ceil((k - 1) / (2.0 * err) * x**3))
    return int(min(max(n, min_n), max_n))


def bin_keys(particles: np.ndarray) -> np.ndarray:
    """Integer histogram bins (N, 3): 0.5 m x 0.5 m x 10 deg (AMCL's pf_kdtree)."""
    return np.stack([
        np.floor(particles[:, 0] / BIN_XY_M),
        np.floor(particles[:, 1] / BIN_XY_M),
        np.floor(wrap_angle(particles[:, 2]) / BIN_TH_RAD),
    ], axis=1).astype(np.int64)


def systematic_indices(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Low-variance resampling in O(N): n indices drawn with one random offset."""
    c = np.cumsum(weights)
    c /= c[-1]
    u = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(c, u, side="right"), len(weights) - 1)


def kld_resample(particles, weights, rng, *, err, z, min_n, max_n):
    """Systematic resampling with the KLD bound (AMCL's pf_update_resample).

    ``max_n`` candidates are drawn systematically and shuffled; the set is the shortest prefix
    whose size reaches the KLD limit of the number of bins that prefix occupies.
    """
    idx = systematic_indices(weights, max_n, rng)
    rng.shuffle(idx)
    cand = particles[idx]
    keys = bin_keys(cand)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, first = np.unique(flat, return_index=True)
    new_bin = np.zeros(len(cand), dtype=np.int64)
    new_bin[first] = 1
    k = np.cumsum(new_bin)  # bins occupied by the first i+1 samples
    b = 2.0 / (9.0 * np.maximum(k - 1, 1))
    limit = np.ceil((k - 1) / (2.0 * err) * (1.0 - b + np.sqrt(b) * z) ** 3)
    limit = np.where(k <= 1, max_n, np.clip(limit, min_n, max_n))
    sizes = np.arange(1, len(cand) + 1)
    ok = np.nonzero(sizes >= limit)[0]
    n = int(ok[0] + 1) if len(ok) else max_n
    return cand[:n].copy()


def cluster_estimate(particles: np.ndarray, weights: np.ndarray):
    """Mean (3,) and covariance (3, 3) of the heaviest cluster of connected occupied bins
    (AMCL's pf_cluster_stats; heading by circular mean, its variance -2 log R)."""
    keys = bin_keys(particles)
    lo = keys.min(axis=0)
    span = keys.max(axis=0) - lo + 1
    if np.prod(span) > 5_000_000:  # pathological spread: one cluster
        labels = np.zeros(len(particles), dtype=np.int64)
    else:
        occ = np.zeros(tuple(span), dtype=bool)
        k = keys - lo
        occ[k[:, 0], k[:, 1], k[:, 2]] = True
        lab, _ = ndimage.label(occ, structure=np.ones((3, 3, 3), dtype=bool))
        # heading wraps around: join clusters touching across -pi/pi
        n_th = int(round(2 * np.pi / BIN_TH_RAD))
        if span[2] >= n_th:
            a, b = lab[:, :, 0], lab[:, :, -1]
            pairs = {(int(x), int(y)) for x, y in zip(a[(a > 0) & (b > 0)],
                                                        b[(a > 0) & (b > 0)], strict=True)}
            for x, y in pairs:
                lab[lab == y] = x
        labels = lab[k[:, 0], k[:, 1], k[:, 2]]
    sums = np.bincount(labels, weights=weights)
    best = labels == int(np.argmax(sums))
    w = weights[best]
    p = particles[best]
    ws = w.sum()
    if ws <= 0:
        w = np.full(len(p), 1.0 / len(p))
        ws = 1.0
    w = w / ws
    mx, my = (w[:, None] * p[:, :2]).sum(axis=0)
    c, s = (w * np.cos(p[:, 2])).sum(), (w * np.sin(p[:, 2])).sum()
    mean = np.array([mx, my, np.arctan2(s, c)])
    cov = np.zeros((3, 3))
    d = p[:, :2] - mean[:2]
    cov[:2, :2] = (w[:, None, None] * d[:, :, None] * d[:, None, :]).sum(axis=0)
    r = min(max(np.hypot(c, s), 1e-12), 1.0)
    cov[2, 2] = -2.0 * np.log(r)
    return mean, cov
