"""numba kernels of the sensor models, parallel over particles (``*_serial``: the same on the
calling thread). Plain-numpy references are in :mod:`gatmo.localization.sensor`; tests check both
agree.

The ray casters are inlined from :mod:`gatmo.maps._kernels`; numba's on-disk cache only notices
changes to *this* file, so after editing the casters there, delete this module's cache files
(``__pycache__/_kernels.*.nbi|nbc``) or touch this file.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from gatmo.maps._kernels import _cast_one, _lut_one, _march_one


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


@njit(cache=True, inline="always")
def _table_particle(particles, i, laser_pose, bx, by, table, inv, ox, oy, off_value):
    h, w = table.shape
    lx, ly, lt = _laser_in_map(particles, i, laser_pose)
    lc = np.cos(lt)
    ls = np.sin(lt)
    p = 1.0
    for j in range(bx.shape[0]):
        ix = int(np.floor((lx + lc * bx[j] - ls * by[j] - ox) * inv))
        iy = int(np.floor((ly + ls * bx[j] + lc * by[j] - oy) * inv))
        if ix < 0 or iy < 0 or ix >= w or iy >= h:
            p += off_value
        else:
            p += table[iy, ix]
    return p


@njit(cache=True, parallel=True)
def likelihood_table_kernel(particles, laser_pose, bx, by, table, res, ox, oy, off_value):
    """The likelihood field with pz^3 precomputed per cell (``table``) and beam endpoints
    precomputed in the laser frame (bx, by): p = 1 + sum_k table[cell(endpoint_k)] (N,).
    Same result as :func:`likelihood_field_kernel` without a trig or exp per beam."""
    n = particles.shape[0]
    out = np.empty(n)
    inv = 1.0 / res
    for i in prange(n):
        out[i] = _table_particle(particles, i, laser_pose, bx, by, table, inv, ox, oy, off_value)
    return out


@njit(cache=True)
def likelihood_table_kernel_serial(particles, laser_pose, bx, by, table, res, ox, oy, off_value):
    """:func:`likelihood_table_kernel` on the calling thread only."""
    n = particles.shape[0]
    out = np.empty(n)
    inv = 1.0 / res
    for i in range(n):
        out[i] = _table_particle(particles, i, laser_pose, bx, by, table, inv, ox, oy, off_value)
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



@njit(cache=True, inline="always")
def _pz_cubed(z, z_hit, inv_denom, const_j, short_j):
    """AMCL's beam term pz^3 for a range error z = observed - expected [m]."""
    pz = z_hit * np.exp(-(z * z) * inv_denom) + const_j
    if z < 0:
        pz += short_j
    return pz * pz * pz


@njit(cache=True, inline="always")
def _beam_march_particle(particles, i, laser_pose, ranges, ca, sa, short, const, sd, inv_res, ox,
                         oy, z_hit, inv_denom, max_t, res, jump_min):
    """The beam model's p = 1 + sum_k pz_k^3 for particle i, ranges by :func:`_march_one`."""
    lx, ly, lt = _laser_in_map(particles, i, laser_pose)
    lc = np.cos(lt)
    ls = np.sin(lt)
    gx = (lx - ox) * inv_res
    gy = (ly - oy) * inv_res
    p = 1.0
    for j in range(ranges.shape[0]):
        t = _march_one(sd, gx, gy, lc * ca[j] - ls * sa[j], ls * ca[j] + lc * sa[j], max_t,
                       jump_min)
        mr = t * res if t < max_t else max_t * res
        p += _pz_cubed(ranges[j] - mr, z_hit, inv_denom, const[j], short[j])
    return p


@njit(cache=True, parallel=True)
def beam_march_kernel(particles, laser_pose, ranges, ca, sa, short, const, sd, res, ox, oy,
                      z_hit, sigma_hit, range_max, jump_min):
    """:func:`beam_kernel` with ranges by exact distance-field marching on ``sd`` (a
    :func:`gatmo.maps.raycast.march_table`), beam directions (ca, sa) = (cos, sin) of the beam
    angles, and the per-beam terms precomputed: ``short`` = z_short lambda exp(-lambda obs),
    ``const`` = z_max if obs >= range_max else z_rand / range_max. (N,)"""
    n = particles.shape[0]
    out = np.empty(n)
    inv_res = 1.0 / res
    inv_denom = 1.0 / (2.0 * sigma_hit * sigma_hit)
    max_t = range_max * inv_res
    for i in prange(n):
        out[i] = _beam_march_particle(particles, i, laser_pose, ranges, ca, sa, short, const, sd,
                                      inv_res, ox, oy, z_hit, inv_denom, max_t, res, jump_min)
    return out


@njit(cache=True)
def beam_march_kernel_serial(particles, laser_pose, ranges, ca, sa, short, const, sd, res, ox,
                             oy, z_hit, sigma_hit, range_max, jump_min):
    """:func:`beam_march_kernel` on the calling thread only (small sets: no thread wake-up)."""
    n = particles.shape[0]
    out = np.empty(n)
    inv_res = 1.0 / res
    inv_denom = 1.0 / (2.0 * sigma_hit * sigma_hit)
    max_t = range_max * inv_res
    for i in range(n):
        out[i] = _beam_march_particle(particles, i, laser_pose, ranges, ca, sa, short, const, sd,
                                      inv_res, ox, oy, z_hit, inv_denom, max_t, res, jump_min)
    return out


@njit(cache=True, inline="always")
def _beam_lut_particle(particles, i, laser_pose, ranges, ca, sa, short, const, index, table,
                       scale_cells, inv_res, ox, oy, z_hit, inv_denom, max_t, res, beam_bins):
    """The beam model's p for particle i, ranges by :func:`_lut_one` (approximate)."""
    lx, ly, lt = _laser_in_map(particles, i, laser_pose)
    lc = np.cos(lt)
    ls = np.sin(lt)
    gx = (lx - ox) * inv_res
    gy = (ly - oy) * inv_res
    bins = table.shape[1]
    u0 = lt * (bins / (2.0 * np.pi))
    u0 -= bins * np.floor(u0 / bins)  # [0, bins); beam_bins in [-bins/2, bins/2)
    p = 1.0
    for j in range(ranges.shape[0]):
        t = _lut_one(index, table, scale_cells, gx, gy, u0 + beam_bins[j],
                     lc * ca[j] - ls * sa[j], ls * ca[j] + lc * sa[j], max_t)
        mr = t * res if t < max_t else max_t * res
        p += _pz_cubed(ranges[j] - mr, z_hit, inv_denom, const[j], short[j])
    return p


@njit(cache=True, parallel=True)
def beam_lut_kernel(particles, laser_pose, ranges, beam_bins, ca, sa, short, const, index, table,
                    scale_cells, res, ox, oy, z_hit, sigma_hit, range_max):
    """:func:`beam_march_kernel` with approximate ranges from a range table
    (:class:`gatmo.maps.raycast.RangeTable`: ``index``, ``table``, ``scale_cells``);
    ``beam_bins`` = beam angles * bins / (2 pi), angles wrapped to [-pi, pi). (N,)"""
    n = particles.shape[0]
    out = np.empty(n)
    inv_res = 1.0 / res
    inv_denom = 1.0 / (2.0 * sigma_hit * sigma_hit)
    max_t = range_max * inv_res
    for i in prange(n):
        out[i] = _beam_lut_particle(particles, i, laser_pose, ranges, ca, sa, short, const,
                                    index, table, scale_cells, inv_res, ox, oy, z_hit, inv_denom,
                                    max_t, res, beam_bins)
    return out


@njit(cache=True)
def beam_lut_kernel_serial(particles, laser_pose, ranges, beam_bins, ca, sa, short, const, index,
                           table, scale_cells, res, ox, oy, z_hit, sigma_hit, range_max):
    """:func:`beam_lut_kernel` on the calling thread only."""
    n = particles.shape[0]
    out = np.empty(n)
    inv_res = 1.0 / res
    inv_denom = 1.0 / (2.0 * sigma_hit * sigma_hit)
    max_t = range_max * inv_res
    for i in range(n):
        out[i] = _beam_lut_particle(particles, i, laser_pose, ranges, ca, sa, short, const,
                                    index, table, scale_cells, inv_res, ox, oy, z_hit, inv_denom,
                                    max_t, res, beam_bins)
    return out
