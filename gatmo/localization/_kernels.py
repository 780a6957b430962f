"""numba kernels of the sensor models, parallel over particles. Plain-numpy references are in
:mod:`gatmo.localization.sensor`; tests check both agree."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from gatmo.maps._kernels import _cast_one


@njit(cache=True, inline="always")
def _laser_in_map(particles, i, laser_pose):
    """Pose (x, y, theta) of the laser of particle i in the map frame."""
    c = np.cos(particles[i, 2])
    s = np.sin(particles[i, 2])
    return (particles[i, 0] + c * laser_pose[0] - s * laser_pose[1],
            particles[i, 1] + s * laser_pose[0] + c * laser_pose[1],
            particles[i, 2] + laser_pose[2])


@njit(cache=True, inline="always")
def _dist_at(dist, res, ox, oy, x, y, max_dist):
    """Field value at a map point; off the map, ``max_dist`` (AMCL's off-map endpoint)."""
    h, w = dist.shape
    ix = int(np.floor((x - ox) / res))
    iy = int(np.floor((y - oy) / res))
    if ix < 0 or iy < 0 or ix >= w or iy >= h:
        return max_dist
    return dist[iy, ix]


@njit(cache=True, parallel=True)
def likelihood_field_kernel(particles, laser_pose, ranges, angles, dist, res, ox, oy, max_dist,
                            z_hit, z_rand, sigma_hit, range_max):
    """ROS AMCL's likelihood field: p = 1 + sum_k pz_k^3 per particle (N,)."""
    n = particles.shape[0]
    b = ranges.shape[0]
    denom = 2.0 * sigma_hit * sigma_hit
    rand = z_rand / range_max
    out = np.empty(n)
    for i in prange(n):
        lx, ly, lt = _laser_in_map(particles, i, laser_pose)
        p = 1.0
        for j in range(b):
            r = ranges[j]
            a = lt + angles[j]
            z = _dist_at(dist, res, ox, oy, lx + r * np.cos(a), ly + r * np.sin(a), max_dist)
            pz = z_hit * np.exp(-(z * z) / denom) + rand
            p += pz * pz * pz
        out[i] = p
    return out


@njit(cache=True, parallel=True)
def likelihood_table_kernel(particles, laser_pose, bx, by, table, res, ox, oy, off_value):
    """The likelihood field with pz^3 precomputed per cell (``table``) and beam endpoints
    precomputed in the laser frame (bx, by): p = 1 + sum_k table[cell(endpoint_k)] (N,).
    Same result as :func:`likelihood_field_kernel` without a trig or exp per beam."""
    n = particles.shape[0]
    b = bx.shape[0]
    h, w = table.shape
    out = np.empty(n)
    inv = 1.0 / res
    for i in prange(n):
        lx, ly, lt = _laser_in_map(particles, i, laser_pose)
        lc = np.cos(lt)
        ls = np.sin(lt)
        p = 1.0
        for j in range(b):
            ix = int(np.floor((lx + lc * bx[j] - ls * by[j] - ox) * inv))
            iy = int(np.floor((ly + ls * bx[j] + lc * by[j] - oy) * inv))
            if ix < 0 or iy < 0 or ix >= w or iy >= h:
                p += off_value
            else:
                p += table[iy, ix]
        out[i] = p
    return out


@njit(cache=True, parallel=True)
def likelihood_field_prob_kernel(particles, laser_pose, ranges, angles, dist, res, ox, oy,
                                 max_dist, z_hit, z_rand, sigma_hit, range_max, use_beam):
    """log of the product of per-beam likelihoods (N,), beams with use_beam False skipped; also
    returns the per-particle distances (N, B) for beam skipping."""
    n = particles.shape[0]
    b = ranges.shape[0]
    denom = 2.0 * sigma_hit * sigma_hit
    rand = z_rand / range_max
    out = np.empty(n)
    zs = np.empty((n, b))
    for i in prange(n):
        lx, ly, lt = _laser_in_map(particles, i, laser_pose)
        logp = 0.0
        for j in range(b):
            r = ranges[j]
            a = lt + angles[j]
            z = _dist_at(dist, res, ox, oy, lx + r * np.cos(a), ly + r * np.sin(a), max_dist)
            zs[i, j] = z
            if use_beam[j]:
                logp += np.log(z_hit * np.exp(-(z * z) / denom) + rand)
        out[i] = logp
    return out, zs


@njit(cache=True, parallel=True)
def beam_kernel(particles, laser_pose, ranges, angles, cells, res, ox, oy, z_hit, z_short,
                z_max, z_rand, sigma_hit, lambda_short, range_max):
    """ROS AMCL's beam model (ray casting): p = 1 + sum_k pz_k^3 per particle (N,)."""
    n = particles.shape[0]
    b = ranges.shape[0]
    denom = 2.0 * sigma_hit * sigma_hit
    out = np.empty(n)
    for i in prange(n):
        lx, ly, lt = _laser_in_map(particles, i, laser_pose)
        p = 1.0
        for j in range(b):
            obs = ranges[j]
            mr = _cast_one(cells, res, ox, oy, lx, ly, lt + angles[j], range_max, True)
            z = obs - mr
            pz = z_hit * np.exp(-(z * z) / denom)
            if z < 0:
                pz += z_short * lambda_short * np.exp(-lambda_short * obs)
            if obs >= range_max:
                pz += z_max
            else:
                pz += z_rand / range_max
            p += pz * pz * pz
        out[i] = p
    return out

