"""numba kernels of the localizer: the sensor models, parallel over particles (``*_serial``: the
same on the calling thread), and the particle-set steps (motion sampling, KLD resampling, the
cluster estimate, the converged check) on the calling thread. Plain-numpy references are in
:mod:`gatmo.localization.sensor`, :mod:`~gatmo.localization.motion` and
:mod:`~gatmo.localization.particles`; tests check both agree.

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


@njit(cache=True)
def unmapped_beams_kernel(particles, laser_pose, ranges, angles, bx, by, unmapped, cells, res, ox,
                          oy, margin):
    """Per beam (B,): how many particles put it in unmapped space: its endpoint (bx, by in the
    laser frame, as for :func:`likelihood_table_kernel`) off the map or on a cell with
    ``unmapped`` set, *and* no occupied cell on the ray before ``range - margin`` (a ray
    through a mapped wall contradicts the map wherever it ends)."""
    n = particles.shape[0]
    h, w = unmapped.shape
    counts = np.zeros(bx.shape[0], dtype=np.int64)
    inv = 1.0 / res
    for i in range(n):
        lx, ly, lt = _laser_in_map(particles, i, laser_pose)
        lc = np.cos(lt)
        ls = np.sin(lt)
        for j in range(bx.shape[0]):
            ix = int(np.floor((lx + lc * bx[j] - ls * by[j] - ox) * inv))
            iy = int(np.floor((ly + ls * bx[j] + lc * by[j] - oy) * inv))
            if ix < 0 or iy < 0 or ix >= w or iy >= h or unmapped[iy, ix]:
                reach = ranges[j] - margin
                if reach <= 0.0 or _cast_one(cells, res, ox, oy, lx, ly, lt + angles[j], reach,
                                             False) >= reach:
                    counts[j] += 1
    return counts


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


# --------------------------------------------------------------------------------------------
# Particle-set kernels: motion sampling, KLD resampling, cluster estimate, converged check.
# They run on the calling thread (a few microseconds of work per thousand particles: waking a
# second thread costs more). Random numbers come in pre-drawn; the numpy references
# (:mod:`gatmo.localization.motion`, :mod:`gatmo.localization.particles`) take the same draws.


@njit(cache=True, inline="always")
def _wrap(a):
    """:func:`gatmo.geometry.wrap_angle` of a scalar, bit for bit: (a + pi) % 2 pi - pi, the
    modulo skipped when a + pi is already in [0, 2 pi) (where it returns its argument)."""
    b = a + np.pi
    if b >= 0.0 and b < 2.0 * np.pi:
        return b - np.pi
    return b % (2.0 * np.pi) - np.pi


@njit(cache=True)
def motion_diff_kernel(particles, rot1, trans, rot2, s1, st, s2, normals):
    """Differential-drive odometry model: particles (N, 3) moved by (rot1, trans, rot2) with
    standard deviations (s1, st, s2) times the standard normals ``normals`` (3, N)."""
    n = particles.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        th = particles[i, 2]
        r1 = _wrap(rot1 - normals[0, i] * s1)
        t = trans - normals[1, i] * st
        r2 = _wrap(rot2 - normals[2, i] * s2)
        out[i, 0] = particles[i, 0] + t * np.cos(th + r1)
        out[i, 1] = particles[i, 1] + t * np.sin(th + r1)
        out[i, 2] = _wrap(th + r1 + r2)
    return out


@njit(cache=True)
def motion_omni_kernel(particles, bearing0, trans, dth, st, sr, ss, normals):
    """Omnidirectional odometry model: translation ``trans`` along ``bearing0`` (relative to
    the particle's heading), rotation ``dth``, noise (st, sr, ss) times ``normals`` (3, N)."""
    n = particles.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        th = particles[i, 2]
        b = bearing0 + th
        cb = np.cos(b)
        sb = np.sin(b)
        t = trans + normals[0, i] * st
        r = dth + normals[1, i] * sr
        s = normals[2, i] * ss
        out[i, 0] = particles[i, 0] + (t * cb + s * sb)
        out[i, 1] = particles[i, 1] + (t * sb - s * cb)
        out[i, 2] = _wrap(th + r)
    return out


_KEY_OFF = 1 << 27  # bin keys within +-2^27 bins (+-67,000 km at 0.5 m) pack exactly


@njit(cache=True, inline="always")
def _bin_key(particles, i, bin_xy, bin_th):
    """AMCL's histogram bin of particle i packed into one int64 (28 + 28 + 6 bits)."""
    kx = np.int64(np.floor(particles[i, 0] / bin_xy)) + _KEY_OFF
    ky = np.int64(np.floor(particles[i, 1] / bin_xy)) + _KEY_OFF
    kt = np.int64(np.floor(_wrap(particles[i, 2]) / bin_th)) + 32
    kx = min(max(kx, 0), (1 << 28) - 1)
    ky = min(max(ky, 0), (1 << 28) - 1)
    kt = min(max(kt, 0), 63)
    return (kx << 34) | (ky << 6) | kt


@njit(cache=True, inline="always")
def _kld_limit(k, err, z, min_n, max_n):
    """Fox 2003's bound for k occupied bins (as :func:`gatmo.localization.particles.kld_limit`,
    with x^3 as x * x * x, the same in the numpy reference)."""
    if k <= 1:
        return max_n
    b = 2.0 / (9.0 * (k - 1))
    x = 1.0 - b + np.sqrt(b) * z
    lim = np.ceil((k - 1) / (2.0 * err) * (x * x * x))
    return int(min(max(lim, min_n), max_n))


@njit(cache=True)
def kld_resample_kernel(particles, weights, u0, u_perm, err, z, min_n, max_n, bin_xy, bin_th):
    """AMCL's KLD resampling (N, 3) -> (n, 3).

    ``max_n`` candidates by systematic resampling (offset ``u0`` in [0, 1)), taken in the order
    of a Fisher-Yates shuffle driven by ``u_perm`` (max_n,) uniforms in [0, 1) (position i is
    swapped with i + floor(u_perm[i] (max_n - i))); the set is the shortest prefix whose size
    reaches the KLD limit of the number of histogram bins it occupies (``max_n`` if none)."""
    m = weights.shape[0]
    c = np.empty(m)
    acc = 0.0
    for i in range(m):
        acc += weights[i]
        c[i] = acc
    last = c[m - 1]
    for i in range(m):
        c[i] /= last
    idx = np.empty(max_n, dtype=np.int64)
    j = 0
    for k in range(max_n):
        u = (u0 + k) / max_n
        while j < m and c[j] <= u:  # searchsorted(c, u, side="right")
            j += 1
        idx[k] = min(j, m - 1)
    size = 1
    while size < 2 * max_n:
        size *= 2
    mask = size - 1
    table = np.full(size, -1, dtype=np.int64)
    bins = 0
    n = max_n
    limit = max_n
    for i in range(max_n):
        s = i + min(np.int64(u_perm[i] * (max_n - i)), max_n - i - 1)
        t = idx[i]
        idx[i] = idx[s]
        idx[s] = t
        key = _bin_key(particles, idx[i], bin_xy, bin_th)
        h = ((key * 0x2545F4914F6CDD1D) >> 20) & mask
        while table[h] != -1 and table[h] != key:
            h = (h + 1) & mask
        if table[h] == -1:
            table[h] = key
            bins += 1
            limit = _kld_limit(bins, err, z, min_n, max_n)
        if i + 1 >= limit:
            n = i + 1
            break
    out = np.empty((n, 3))
    for i in range(n):
        out[i, 0] = particles[idx[i], 0]
        out[i, 1] = particles[idx[i], 1]
        out[i, 2] = particles[idx[i], 2]
    return out


@njit(cache=True, inline="always")
def _find(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True)
def cluster_labels_kernel(particles, bin_xy, bin_th, n_th, max_cells):
    """Cluster label per particle (N,) int64: connected occupied histogram bins (26-neighbours),
    labels numbered from 1 in raster order (x, y, heading bin) of each cluster's first bin, as
    ``scipy.ndimage.label``; clusters touching across -pi/pi at the same (x, y) are joined under
    the smaller label. All 0 (one cluster) when the bins' bounding box exceeds ``max_cells``."""
    n = particles.shape[0]
    kx = np.empty(n, dtype=np.int64)
    ky = np.empty(n, dtype=np.int64)
    kt = np.empty(n, dtype=np.int64)
    for i in range(n):
        kx[i] = np.int64(np.floor(particles[i, 0] / bin_xy))
        ky[i] = np.int64(np.floor(particles[i, 1] / bin_xy))
        kt[i] = np.int64(np.floor(_wrap(particles[i, 2]) / bin_th))
    x0, y0, t0 = kx.min(), ky.min(), kt.min()
    sx = kx.max() - x0 + 1
    sy = ky.max() - y0 + 1
    st = kt.max() - t0 + 1
    labels = np.zeros(n, dtype=np.int64)
    if float(sx) * float(sy) * float(st) > max_cells:
        return labels
    lab = np.zeros((sx, sy, st), dtype=np.int32)
    for i in range(n):
        lab[kx[i] - x0, ky[i] - y0, kt[i] - t0] = -1
    stack = np.empty((n, 3), dtype=np.int64)
    nl = 0
    for a in range(sx):
        for b in range(sy):
            for c in range(st):
                if lab[a, b, c] != -1:
                    continue
                nl += 1
                lab[a, b, c] = np.int32(nl)
                stack[0, 0], stack[0, 1], stack[0, 2] = a, b, c
                top = 1
                while top > 0:
                    top -= 1
                    p, q, r = stack[top, 0], stack[top, 1], stack[top, 2]
                    for dp in range(max(p - 1, 0), min(p + 2, sx)):
                        for dq in range(max(q - 1, 0), min(q + 2, sy)):
                            for dr in range(max(r - 1, 0), min(r + 2, st)):
                                if lab[dp, dq, dr] == -1:
                                    lab[dp, dq, dr] = np.int32(nl)
                                    stack[top, 0], stack[top, 1], stack[top, 2] = dp, dq, dr
                                    top += 1
    parent = np.arange(nl + 1)
    if st >= n_th:
        for a in range(sx):
            for b in range(sy):
                la, lb = np.int64(lab[a, b, 0]), np.int64(lab[a, b, st - 1])
                if la > 0 and lb > 0:
                    ra, rb = _find(parent, la), _find(parent, lb)
                    if ra < rb:
                        parent[rb] = ra
                    elif rb < ra:
                        parent[ra] = rb
    for i in range(n):
        labels[i] = _find(parent, np.int64(lab[kx[i] - x0, ky[i] - y0, kt[i] - t0]))
    return labels


@njit(cache=True)
def cluster_stats_kernel(particles, weights, labels):
    """Weighted mean (3,) and covariance (3, 3) of the heaviest cluster (the smallest label of
    the largest weight sum, sums accumulated in particle order); heading by circular mean, its
    variance -2 log R. Uniform weights within the cluster when its weight sum is not > 0."""
    n = particles.shape[0]
    sums = np.zeros(labels.max() + 1)
    counts = np.zeros(labels.max() + 1, dtype=np.int64)
    for i in range(n):
        sums[labels[i]] += weights[i]
        counts[labels[i]] += 1
    best = labels[0]
    for k in range(sums.shape[0]):
        if counts[k] > 0 and (sums[k] > sums[best] or (sums[k] == sums[best] and k < best)):
            best = k
    ws = 0.0
    cnt = 0
    for i in range(n):
        if labels[i] == best:
            ws += weights[i]
            cnt += 1
    uniform = not ws > 0.0
    mx = my = cc = ss = 0.0
    for i in range(n):
        if labels[i] == best:
            w = 1.0 / cnt if uniform else weights[i] / ws
            mx += w * particles[i, 0]
            my += w * particles[i, 1]
            cc += w * np.cos(particles[i, 2])
            ss += w * np.sin(particles[i, 2])
    cxx = cxy = cyy = 0.0
    for i in range(n):
        if labels[i] == best:
            w = 1.0 / cnt if uniform else weights[i] / ws
            dx = particles[i, 0] - mx
            dy = particles[i, 1] - my
            cxx += w * dx * dx
            cxy += w * dx * dy
            cyy += w * dy * dy
    mean = np.array([mx, my, np.arctan2(ss, cc)])
    cov = np.zeros((3, 3))
    cov[0, 0] = cxx
    cov[0, 1] = cov[1, 0] = cxy
    cov[1, 1] = cyy
    r = min(max(np.hypot(cc, ss), 1e-12), 1.0)
    cov[2, 2] = -2.0 * np.log(r)
    return mean, cov


@njit(cache=True)
def converged_kernel(particles, dist):
    """AMCL's pf->converged: every particle within ``dist`` of the mean in x and in y."""
    n = particles.shape[0]
    mx = 0.0
    my = 0.0
    for i in range(n):
        mx += particles[i, 0]
        my += particles[i, 1]
    mx /= n
    my /= n
    for i in range(n):
        if abs(particles[i, 0] - mx) > dist or abs(particles[i, 1] - my) > dist:
            return False
    return True
