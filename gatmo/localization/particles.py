"""Particle-set machinery of AMCL: KLD-sampling bound, systematic resampling, clusters.

The filter runs numba kernels (:mod:`gatmo.localization._kernels`); the ``*_reference``
functions here are the same steps in numpy on the same random draws, for the tests.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from gatmo.geometry import wrap_angle

BIN_XY_M = 0.5
BIN_TH_RAD = np.radians(10.0)
N_TH_BINS = int(round(2 * np.pi / BIN_TH_RAD))
#: above this many cells in the bounding box of the occupied bins the particles are taken as
#: one cluster (a pathological spread)
CLUSTER_MAX_CELLS = 5_000_000


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


def systematic_indices_from(weights: np.ndarray, n: int, u0: float) -> np.ndarray:
    """Low-variance resampling in O(N): n indices, offset u0 in [0, 1)."""
    c = np.cumsum(weights)
    c /= c[-1]
    u = (u0 + np.arange(n)) / n
    return np.minimum(np.searchsorted(c, u, side="right"), len(weights) - 1)


def systematic_indices(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Low-variance resampling in O(N): n indices drawn with one random offset."""
    return systematic_indices_from(weights, n, rng.random())


def kld_resample(particles, weights, rng, *, err, z, min_n, max_n):
    """Systematic resampling with the KLD bound (AMCL's pf_update_resample).

    ``max_n`` candidates are drawn systematically and shuffled; the set is the shortest prefix
    whose size reaches the KLD limit of the number of bins that prefix occupies. Draws
    ``max_n + 1`` uniforms (the offset, then the shuffle's) and runs the numba kernel."""
    from gatmo.localization import _kernels as K

    u = rng.random(max_n + 1)
    return K.kld_resample_kernel(np.ascontiguousarray(particles, dtype=np.float64),
                                 np.ascontiguousarray(weights, dtype=np.float64), u[0], u[1:],
                                 float(err), float(z), int(min_n), int(max_n), BIN_XY_M,
                                 BIN_TH_RAD)


def kld_resample_reference(particles, weights, u0, u_perm, *, err, z, min_n, max_n):
    """numpy reference of :func:`kld_resample` on given uniforms: offset ``u0`` and the
    shuffle's ``u_perm`` (max_n,): position i swaps with i + floor(u_perm[i] (max_n - i))."""
    idx = systematic_indices_from(weights, max_n, u0)
    for i in range(max_n):  # Fisher-Yates, front to back
        s = i + min(int(u_perm[i] * (max_n - i)), max_n - i - 1)
        idx[i], idx[s] = idx[s], idx[i]
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
    x = 1.0 - b + np.sqrt(b) * z
    limit = np.ceil((k - 1) / (2.0 * err) * (x * x * x))
    limit = np.where(k <= 1, max_n, np.clip(limit, min_n, max_n))
    sizes = np.arange(1, len(cand) + 1)
    ok = np.nonzero(sizes >= limit)[0]
    n = int(ok[0] + 1) if len(ok) else max_n
    return cand[:n].copy()


def cluster_estimate(particles: np.ndarray, weights: np.ndarray):
    """Mean (3,) and covariance (3, 3) of the heaviest cluster of connected occupied bins
    (AMCL's pf_cluster_stats; heading by circular mean, its variance -2 log R). Ties between
    clusters go to the one whose first bin comes first in (x, y, heading) order."""
    from gatmo.localization import _kernels as K

    parts = np.ascontiguousarray(particles, dtype=np.float64)
    labels = K.cluster_labels_kernel(parts, BIN_XY_M, BIN_TH_RAD, N_TH_BINS, CLUSTER_MAX_CELLS)
    return K.cluster_stats_kernel(parts, np.ascontiguousarray(weights, dtype=np.float64),
                                  labels)


def cluster_labels_reference(particles: np.ndarray) -> np.ndarray:
    """numpy reference of the kernel's cluster labels (N,): ``ndimage.label`` with 26-neighbours,
    clusters touching across -pi/pi at the same (x, y) joined under the smaller label."""
    keys = bin_keys(particles)
    lo = keys.min(axis=0)
    span = keys.max(axis=0) - lo + 1
    if np.prod(span.astype(float)) > CLUSTER_MAX_CELLS:  # pathological spread: one cluster
        return np.zeros(len(particles), dtype=np.int64)
    occ = np.zeros(tuple(span), dtype=bool)
    k = keys - lo
    occ[k[:, 0], k[:, 1], k[:, 2]] = True
    lab, nl = ndimage.label(occ, structure=np.ones((3, 3, 3), dtype=bool))
    parent = np.arange(nl + 1)

    def find(a):
        while parent[a] != a:
            a = parent[a]
        return a

    if span[2] >= N_TH_BINS:  # heading wraps around
        a, b = lab[:, :, 0], lab[:, :, -1]
        both = (a > 0) & (b > 0)
        for x, y in zip(a[both], b[both], strict=True):
            rx, ry = find(x), find(y)
            parent[max(rx, ry)] = min(rx, ry)
    roots = np.array([find(i) for i in range(nl + 1)])
    return roots[lab[k[:, 0], k[:, 1], k[:, 2]]].astype(np.int64)


def cluster_estimate_reference(particles: np.ndarray, weights: np.ndarray):
    """numpy reference of :func:`cluster_estimate`."""
    labels = cluster_labels_reference(particles)
    sums = np.bincount(labels, weights=weights)
    sums[np.bincount(labels) == 0] = -np.inf  # labels merged away
    best = labels == int(np.argmax(sums))
    w = weights[best]
    p = particles[best]
    ws = w.sum()
    if not ws > 0:
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


def is_converged(particles: np.ndarray, dist_m: float) -> bool:
    """AMCL's pf->converged: all particles within ``dist_m`` of the mean in x and y (kernel)."""
    from gatmo.localization import _kernels as K

    return bool(K.converged_kernel(np.ascontiguousarray(particles, dtype=np.float64),
                                   float(dist_m)))


def is_converged_reference(particles: np.ndarray, dist_m: float) -> bool:
    """numpy reference of :func:`is_converged`."""
    mean = particles[:, :2].mean(axis=0)
    return bool(np.all(np.abs(particles[:, :2] - mean) <= dist_m))
