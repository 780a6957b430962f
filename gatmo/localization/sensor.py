"""Laser sensor models of AMCL: likelihood field, likelihood field (prob) with beam skipping, and
the beam model. ``weigh`` returns per-particle *log* weights so products never underflow."""

from __future__ import annotations

import numpy as np

from gatmo.datasets.types import Scan
from gatmo.errors import ConfigError
from gatmo.maps.grid import FREE, OCCUPIED
from gatmo.maps.likelihood import LikelihoodField


def segment_weights(ranges_m: np.ndarray, angles_rad: np.ndarray, jump_m: float,
                    max_beams: int) -> np.ndarray:
    """Per-beam weights (B,) that make each segment of the scan count as at most ``max_beams``
    beams. A segment is a run of beams adjacent in the selection (sorted by angle) whose
    ranges differ by at most ``jump_m`` from one to the next and with no gap in angle of more
    than twice the median step. ``ranges_m``, ``angles_rad``: (B,) selected beams."""
    b = len(ranges_m)
    if b == 0:
        return np.zeros(0)
    cut = np.zeros(b, dtype=bool)
    if b > 1:
        da = np.abs(np.diff(angles_rad))
        step = float(np.median(da)) if np.any(da > 0) else 0.0
        cut[1:] = (np.abs(np.diff(ranges_m)) > jump_m) | (da > 2.0 * step + 1e-9)
    seg = np.cumsum(cut)
    n = np.bincount(seg)
    return np.minimum(1.0, max_beams / n[seg])


def beam_step(num_beams: int, max_beams: int) -> int:
    """AMCL's beam subsampling step: every step-th beam is used."""
    return max(1, (num_beams - 1) // max(max_beams - 1, 1))


def select_beams(scan: Scan, max_beams: int, range_min_m: float | None,
                 range_max_m: float | None, keep_max_range: bool):
    """AMCL's beam subsampling (step = (n - 1) // (max_beams - 1)) and range gating.

    Returns (ranges (B,), angles (B,), range_max). Readings that are NaN/inf/negative or below
    range_min are dropped; readings at or above range_max are dropped unless ``keep_max_range``
    (the beam model scores them as max-range readings). SICK "no return" values count as max.
    """
    rmax = float(range_max_m if range_max_m is not None else scan.range_max_m)
    rmin = float(range_min_m if range_min_m is not None else scan.range_min_m)
    n = scan.num_beams
    idx = np.arange(0, n, beam_step(n, max_beams))
    r = scan.ranges_m[idx].copy()
    a = scan.angles_rad[idx]
    with np.errstate(invalid="ignore"):
        finite = np.isfinite(r) & (r > rmin)
        r[finite & (r >= 80.0)] = rmax  # SICK no-return
        at_max = finite & (r >= rmax)
    keep = finite & (~at_max | keep_max_range)
    r = np.where(at_max, rmax, r)
    return r[keep], a[keep], rmax


def likelihood_field_reference(particles, laser_pose, ranges, angles, field: LikelihoodField,
                               z_hit, z_rand, sigma_hit, range_max):
    """numpy reference of the likelihood field kernel (N,) p = 1 + sum pz^3."""
    from gatmo.geometry import compose

    lp = compose(particles, laser_pose[None, :])
    a = lp[:, 2:3] + angles[None, :]
    hx = lp[:, 0:1] + ranges[None, :] * np.cos(a)
    hy = lp[:, 1:2] + ranges[None, :] * np.sin(a)
    z = field.distance_at(np.stack([hx.ravel(), hy.ravel()], axis=1)).reshape(hx.shape)
    pz = z_hit * np.exp(-(z**2) / (2 * sigma_hit**2)) + z_rand / range_max
    return 1.0 + (pz**3).sum(axis=1)


def beam_reference(particles, laser_pose, ranges, angles, grid, z_hit, z_short, z_max, z_rand,
                   sigma_hit, lambda_short, range_max):
    """numpy reference of the beam model (N,)."""
    from gatmo.geometry import compose
    from gatmo.maps.raycast import _cast_rays_reference

    lp = compose(particles, laser_pose[None, :])
    out = np.empty(len(particles))
    for i, pose in enumerate(lp):
        mr = _cast_rays_reference(grid, pose, angles, range_max, step_m=grid.resolution_m / 100)
        z = ranges - mr
        pz = z_hit * np.exp(-(z**2) / (2 * sigma_hit**2))
        pz = pz + np.where(z < 0, z_short * lambda_short * np.exp(-lambda_short * ranges), 0.0)
        pz = pz + np.where(ranges >= range_max, z_max, z_rand / range_max)
        out[i] = 1.0 + (pz**3).sum()
    return out


def unmapped_beams_reference(particles, laser_pose, ranges, angles, grid, unmapped, margin):
    """numpy reference of :func:`gatmo.localization._kernels.unmapped_beams_kernel` (B,)."""
    from gatmo.geometry import compose
    from gatmo.maps.raycast import cast_rays

    lp = compose(particles, laser_pose[None, :])
    counts = np.zeros(len(ranges), dtype=np.int64)
    for pose in lp:
        a = pose[2] + angles
        end = np.stack([pose[0] + ranges * np.cos(a), pose[1] + ranges * np.sin(a)], axis=1)
        c = grid.world_to_cell(end)
        ok = grid.in_bounds(c)
        off = ~ok
        off[ok] = unmapped[c[ok, 1], c[ok, 0]] > 0
        for j in np.flatnonzero(off):
            reach = ranges[j] - margin
            if reach <= 0 or cast_rays(grid, pose, angles[j : j + 1], reach,
                                       stop_at_unknown=False)[0] >= reach:
                counts[j] += 1
    return counts


class SensorModel:
    """Weighs particles against a scan with one of AMCL's laser models.

    With ``cfg.skip_unmapped_beams`` the likelihood-field models leave out the beams that end in
    unmapped space for most particles (:meth:`mapped_beams`): an unknown cell far from every
    obstacle says nothing about the pose, while AMCL scores such an endpoint as a miss, which
    makes every particle that can explain the beam by some mapped wall win, pulling the set
    towards the map when the robot drives out of it. ``last_unmapped_beams``: how many beams
    the last :meth:`weigh` left out that way.
    """

    #: beam model ray casters: "march" (exact: jumps on the distance transform, cell walk near
    #: obstacles), "dda" (exact: cell walk all the way, the reference kernel), "lut" (approximate:
    #: ranges precomputed per free cell and heading bin, see :mod:`gatmo.maps.raycast`)
    RAY_CASTERS = ("march", "dda", "lut")
    #: below this many beam evaluations per update (about 20 ms of work on one thread) the
    #: kernels run on the calling thread: on a shared 2-core machine waking a second thread
    #: measured 5-7 ms of stall per call, more than it saves on smaller sets
    #: ("dda", the reference, is always parallel)
    PARALLEL_MIN_EVALS = {"march": 250_000, "lut": 1_000_000, "field": 4_000_000}

    #: the particles (at most about this many, evenly spaced in the set) that vote on which
    #: beams end in unmapped space
    UNMAPPED_VOTERS = 64

    def __init__(self, field: LikelihoodField, cfg, ray_caster: str = "march") -> None:
        self.field = field
        self.cfg = cfg
        self.ray_caster = ray_caster
        self.last_unmapped_beams = 0
        self.last_gated = False
        self.last_explained_fraction = float("nan")
        self._unmapped = None
        self._unmapped_key = None
        self._table = None
        self._table_key = None
        self._march = None
        self._march_key = None
        self._lut = None
        self._lut_key = None

    def _pz3_table(self, rmax: float):
        """pz^3 per cell, refreshed (by region) when the field or range_max changes."""
        c = self.cfg
        f = self.field

        def pz3(d):
            return (c.z_hit * np.exp(-(d**2) / (2 * c.sigma_hit_m**2)) + c.z_rand / rmax) ** 3

        key = (rmax, id(f.dist_m), f.dist_m.shape)
        if self._table is None or self._table_key != key:
            self._table = pz3(f.dist_m)
            self._table_version = f.version
            self._table_key = key
        elif self._table_version != f.version:
            missed = f.version - self._table_version
            if missed > len(f.changed_windows):
                self._table = pz3(f.dist_m)
            else:
                for x0, y0, x1, y1 in f.changed_windows[-missed:]:
                    self._table[y0:y1, x0:x1] = pz3(f.dist_m[y0:y1, x0:x1])
            self._table_version = f.version
        return self._table, float(pz3(np.float64(f.max_dist_m)))

    def _unmapped_table(self) -> np.ndarray:
        """uint8 per cell: 1 where the map says nothing (an unknown cell further than
        3 sigma_hit from every occupied cell), refreshed by region when the map changes."""
        f = self.field
        reach = 3.0 * self.cfg.sigma_hit_m

        def unmapped(cells, dist):
            return ((cells != FREE) & (cells != OCCUPIED) & (dist >= reach)).astype(np.uint8)

        key = (reach, id(f.dist_m), f.dist_m.shape)
        if self._unmapped is None or self._unmapped_key != key:
            self._unmapped = unmapped(f.grid.cells, f.dist_m)
            self._unmapped_version = f.version
            self._unmapped_key = key
        elif self._unmapped_version != f.version:
            missed = f.version - self._unmapped_version
            if missed > len(f.changed_windows):
                self._unmapped = unmapped(f.grid.cells, f.dist_m)
            else:
                for x0, y0, x1, y1 in f.changed_windows[-missed:]:
                    self._unmapped[y0:y1, x0:x1] = unmapped(f.grid.cells[y0:y1, x0:x1],
                                                            f.dist_m[y0:y1, x0:x1])
            self._unmapped_version = f.version
        return self._unmapped

    def mapped_beams(self, particles: np.ndarray, laser_pose: np.ndarray, ranges: np.ndarray,
                     angles: np.ndarray) -> np.ndarray:
        """Beams (B,) bool worth weighing: False where, for more than half of the voting
        particles (up to :attr:`UNMAPPED_VOTERS`, evenly spaced through the set), the endpoint
        lies in unmapped space (:meth:`_unmapped_table`, or off the map) and the ray gets there
        without crossing an occupied cell (up to 3 sigma_hit before the endpoint)."""
        from gatmo.localization import _kernels as K

        g = self.field.grid
        voters = np.ascontiguousarray(particles[:: max(1, len(particles) // self.UNMAPPED_VOTERS)])
        counts = K.unmapped_beams_kernel(voters, laser_pose, ranges, angles,
                                         ranges * np.cos(angles), ranges * np.sin(angles),
                                         self._unmapped_table(), g.cells, g.resolution_m,
                                         g.origin_xytheta[0], g.origin_xytheta[1],
                                         3.0 * self.cfg.sigma_hit_m)
        return 2 * counts <= len(voters)

    def _march_table(self) -> np.ndarray:
        """The beam model's march table, refreshed (by region) when the map changes."""
        from gatmo.maps.raycast import march_table, update_march_table

        f = self.field
        key = (id(f.grid.cells), f.grid.cells.shape)
        if self._march is None or self._march_key != key:
            self._march = march_table(f.grid)
            self._march_version = f.version
            self._march_key = key
        elif self._march_version != f.version:
            missed = f.version - self._march_version
            if missed > len(f.changed_windows):
                self._march = march_table(f.grid)
            else:
                for win in f.changed_windows[-missed:]:
                    update_march_table(self._march, f.grid, win)
            self._march_version = f.version
        return self._march

    def _range_lut(self, rmax: float):
        """The beam model's range table (ray_caster "lut"), refreshed (by region) when the map
        changes: only the rays that cross a changed window are recast."""
        from gatmo.maps.raycast import RangeTable

        f = self.field
        march = self._march_table()
        key = (id(f.grid.cells), f.grid.cells.shape, rmax)
        if self._lut is None or self._lut_key != key:
            self._lut = RangeTable(f.grid, rmax, march=march)
            self._lut_key = key
            self._lut_version = f.version
        elif self._lut_version != f.version:
            missed = f.version - self._lut_version
            if missed > len(f.changed_windows):
                self._lut = RangeTable(f.grid, rmax, march=march)
            else:
                for win in f.changed_windows[-missed:]:
                    self._lut.update(f.grid, win, march)
            self._lut_version = f.version
        return self._lut

    def _beam(self, parts, lp, ranges, angles, rmax):
        """p = 1 + sum pz^3 (N,) of the beam model with the selected ray caster."""
        from gatmo.localization import _kernels as K
        from gatmo.maps.raycast import MARCH_JUMP_MIN_CELLS

        c = self.cfg
        g = self.field.grid
        ox, oy = g.origin_xytheta[:2]
        if self.ray_caster not in self.RAY_CASTERS:
            raise ConfigError(f"ray_caster must be one of {self.RAY_CASTERS}, "
                              f"got {self.ray_caster!r}", field="ray_caster")
        par = len(parts) * len(ranges) >= self.PARALLEL_MIN_EVALS.get(self.ray_caster, 0)
        if self.ray_caster == "dda":
            return K.beam_kernel(parts, lp, ranges, angles, g.cells, g.resolution_m, ox, oy,
                                 c.z_hit, c.z_short, c.z_max, c.z_rand, c.sigma_hit_m,
                                 c.lambda_short, rmax)
        short = c.z_short * c.lambda_short * np.exp(-c.lambda_short * ranges)
        const = np.where(ranges >= rmax, c.z_max, c.z_rand / rmax)
        ca = np.cos(angles)
        sa = np.sin(angles)
        if self.ray_caster == "lut":
            lut = self._range_lut(rmax)
            kern = K.beam_lut_kernel if par else K.beam_lut_kernel_serial
            return kern(parts, lp, ranges, lut.beam_bins(angles), ca, sa, short, const,
                        lut.index, lut.ranges, lut.scale_cells, g.resolution_m, ox, oy, c.z_hit,
                        c.sigma_hit_m, rmax)
        kern = K.beam_march_kernel if par else K.beam_march_kernel_serial
        return kern(parts, lp, ranges, ca, sa, short, const, self._march_table(),
                    g.resolution_m, ox, oy, c.z_hit, c.sigma_hit_m, rmax, MARCH_JUMP_MIN_CELLS)

    def weigh(self, particles: np.ndarray, scan: Scan, converged: bool,
              gate_unexplained: bool = False,
              predicted_xytheta: np.ndarray | None = None,
              withheld: np.ndarray | None = None) -> tuple[np.ndarray, int]:
        """Log weights (N,) and the number of beams used (0: nothing to weigh).
        ``gate_unexplained``: apply ``min_explained_beam_fraction`` (the localizer asks for it
        once converged, and for at most ``max_coast_m`` of travel; ``last_gated`` says whether
        it held the scan back; ``last_explained_fraction`` is the fraction measured).
        ``predicted_xytheta`` (3,): the filter's estimate carried by odometry to this scan
        [m, m, rad], map frame, where ``explained_at: prediction`` tests the beams.
        ``withheld`` (B,) bool: beams the caller withheld as unexplained (set to NaN); the
        gate counts those among the selected beams as unexplained."""
        from gatmo.localization import _kernels as K

        c = self.cfg
        beam = c.laser_model == "beam"
        ranges, angles, rmax = select_beams(scan, c.max_beams, c.laser_min_range_m,
                                            c.laser_max_range_m, keep_max_range=beam)
        self.last_unmapped_beams = 0
        self.last_gated = False
        if len(ranges) == 0:
            return np.zeros(len(particles)), 0
        g = self.field.grid
        ox, oy = g.origin_xytheta[:2]
        lp = np.ascontiguousarray(scan.laser_pose_xytheta, dtype=np.float64)
        parts = np.ascontiguousarray(particles, dtype=np.float64)
        if c.skip_unmapped_beams and not beam:
            keep = self.mapped_beams(parts, lp, ranges, angles)
            if not keep.all():
                self.last_unmapped_beams = int((~keep).sum())
                if keep.mean() < c.min_mapped_beam_fraction or not keep.any():
                    return np.zeros(len(particles)), 0
                ranges, angles = ranges[keep], angles[keep]
        if c.laser_model == "likelihood_field":
            table, off = self._pz3_table(rmax)
            par = len(parts) * len(ranges) >= self.PARALLEL_MIN_EVALS["field"]
            kern = K.likelihood_table_kernel if par else K.likelihood_table_kernel_serial
            p = kern(parts, lp, ranges * np.cos(angles), ranges * np.sin(angles), table,
                     g.resolution_m, ox, oy, off)
            return np.log(p), len(ranges)
        if c.laser_model == "beam":
            return np.log(self._beam(parts, lp, ranges, angles, rmax)), len(ranges)
        use = np.ones(len(ranges), dtype=np.bool_)
        logp, zs = K.likelihood_field_prob_kernel(parts, lp, ranges, angles, self.field.dist_m,
                                                  g.resolution_m, ox, oy,
                                                  self.field.max_dist_m, c.z_hit, c.z_rand,
                                                  c.sigma_hit_m, rmax, use)
        # A beam is explained where its hit term outweighs its random term,
        # z_hit exp(-d^2 / 2 sigma^2) > z_rand / range_max; the fraction per particle, then
        # for the best tenth of them: a cloud spread by coasting is not unexplained because
        # most of its particles are off
        # (measured only when the gate is on: it costs a pass over particles x beams)
        if c.min_explained_beam_fraction > 0.0:
            ratio = c.z_hit * rmax / max(c.z_rand, 1e-12)
            d_max = c.sigma_hit_m * np.sqrt(2.0 * np.log(ratio)) if ratio > 1.0 else 0.0
            if c.explained_at == "prediction" and predicted_xytheta is not None:
                at = np.ascontiguousarray(np.reshape(predicted_xytheta, (1, 3)), dtype=np.float64)
                _, zs_at = K.likelihood_field_prob_kernel(
                    at, lp, ranges, angles, self.field.dist_m, g.resolution_m, ox, oy,
                    self.field.max_dist_m, c.z_hit, c.z_rand, c.sigma_hit_m, rmax, use)
                explained = float((zs_at[0] < d_max).sum())
            else:
                explained = float(np.quantile((zs < d_max).sum(axis=1), 0.9))
            n_withheld = 0
            if withheld is not None:
                step = beam_step(scan.num_beams, c.max_beams)
                n_withheld = int(np.count_nonzero(np.asarray(withheld, dtype=bool)[::step]))
            self.last_explained_fraction = explained / (len(ranges) + n_withheld)
        if gate_unexplained and self.last_explained_fraction < c.min_explained_beam_fraction:
            self.last_gated = True
            return np.zeros(len(particles)), 0
        if c.do_beamskip and converged:
            # AMCL: skip beams that most particles cannot explain (likely unmapped obstacles),
            # unless that would skip too many of them
            explained = (zs < c.beam_skip_distance_m).mean(axis=0) >= c.beam_skip_threshold
            if explained.mean() >= 1.0 - c.beam_skip_error_threshold:
                use = explained
        if c.segment_balanced or not use.all():
            w = (segment_weights(ranges, angles, c.segment_jump_m, c.segment_max_beams)
                 if c.segment_balanced else np.ones(len(ranges)))
            pz = c.z_hit * np.exp(-(zs[:, use] ** 2) / (2 * c.sigma_hit_m**2)) + c.z_rand / rmax
            logp = np.log(pz) @ w[use]
        return logp, len(ranges)
