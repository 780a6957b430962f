"""Monte Carlo localization as ROS/Nav2 AMCL runs it (``laserReceived``), as a library.

Per scan: the odometry step since the last filter update is accumulated; once it exceeds
``update_min_d`` / ``update_min_a`` (or on the first scan) the particles are moved by the motion
model, weighed by the sensor model, the recovery averages updated, and the set resampled every
``resample_interval`` updates with KLD-sampling. Between filter updates the published pose is
the last estimate carried forward by odometry (what AMCL's map->odom transform gives).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from gatmo.datasets.types import Scan
from gatmo.errors import MapError
from gatmo.geometry import wrap_angle
from gatmo.localization.config import AmclConfig
from gatmo.localization.motion import sample_motion
from gatmo.localization.particles import cluster_estimate, is_converged, kld_resample
from gatmo.localization.sensor import SensorModel
from gatmo.maps.grid import OCCUPIED, OccupancyGrid
from gatmo.maps.likelihood import LikelihoodField


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _compose(a, b) -> np.ndarray:
    """:func:`gatmo.geometry.compose` of two single poses with scalar math (per-scan cost)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], _wrap(a[2] + b[2])])


def _relative(a, b) -> np.ndarray:
    """:func:`gatmo.geometry.relative` (pose b in the frame of a) of two single poses."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, _wrap(b[2] - a[2])])


@dataclass
class PoseEstimate:
    """The localizer's answer for one scan.

    pose_xytheta: base pose in the map frame (3,); cov: (3, 3) of the heaviest cluster at the
    last filter update; updated: the filter ran a sensor update on this scan; converged: all
    particles within ``converged_dist_m`` of the mean (AMCL's pf->converged).
    """

    stamp_s: float
    pose_xytheta: np.ndarray
    cov: np.ndarray
    n_particles: int
    converged: bool
    updated: bool
    n_valid_beams: int = 0


@dataclass
class LocalizerStats:
    scans: int = 0
    sensor_updates: int = 0
    skipped_no_valid_beams: int = 0
    odom_resets: int = 0
    random_injected: int = 0
    tempered_updates: int = 0
    unmapped_beams: int = 0
    unexplained_skipped: int = 0  # scans held back by min_explained_beam_fraction
    map_region_updates: int = 0
    update_ms: list = field(default_factory=list)

    def as_dict(self) -> dict:
        ms = np.array(self.update_ms) if self.update_ms else np.array([np.nan])
        return {"scans": self.scans, "sensor_updates": self.sensor_updates,
                "skipped_no_valid_beams": self.skipped_no_valid_beams,
                "odom_resets": self.odom_resets, "random_injected": self.random_injected,
                "unmapped_beams": self.unmapped_beams,
                "unexplained_skipped": self.unexplained_skipped,
                "map_region_updates": self.map_region_updates,
                "ms_per_update_median": float(np.median(ms))}


class MonteCarloLocalizer:
    """AMCL as a library. ``grid`` is copied: map changes go through :meth:`set_map` or
    :meth:`update_map_region`."""

    def __init__(self, grid: OccupancyGrid, cfg: AmclConfig,
                 rng: np.random.Generator | None = None) -> None:
        self.cfg = cfg
        self.rng = rng if rng is not None else np.random.default_rng(cfg.seed)
        self.field = LikelihoodField(grid.copy(), cfg.laser_likelihood_max_dist_m)
        self.sensor = SensorModel(self.field, cfg, ray_caster=cfg.beam_ray_caster)
        self._free_xy: np.ndarray | None = None
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.stats = LocalizerStats()
        self._odom_at_update: np.ndarray | None = None
        self._odom_last: np.ndarray | None = None
        self._est = np.zeros(3)
        self._cov = np.eye(3)
        self._converged = False
        self._updates_since_resample = 0
        self._force_update = True
        self._coast_m = 0.0  # odometry-only travel on unexplained scans (max_coast_m)
        if cfg.initial_pose_xytheta is not None:
            self.set_initial_pose(np.array(cfg.initial_pose_xytheta), self.initial_cov())
        elif cfg.global_localization_on_start:
            self.global_localization()

    @classmethod
    def from_config(cls, cfg: AmclConfig, grid: OccupancyGrid,
                    rng: np.random.Generator | None = None) -> MonteCarloLocalizer:
        return cls(grid, cfg, rng)

    # ------------------------------------------------------------------ set-up
    @property
    def grid(self) -> OccupancyGrid:
        return self.field.grid

    def initial_cov(self) -> np.ndarray:
        c = self.cfg
        return np.diag([c.initial_cov_xx_m2, c.initial_cov_yy_m2, c.initial_cov_aa_rad2])

    def start_refusal(self, pose_xytheta) -> str | None:
        """Why :meth:`set_initial_pose` would refuse the map pose (3,): "outside the map", "in
        an occupied cell", or None if it would not."""
        cell = self.grid.world_to_cell(np.asarray(pose_xytheta, dtype=float)[None, :2])
        if not self.grid.in_bounds(cell)[0]:
            return "outside the map"
        if self.grid.cells[cell[0, 1], cell[0, 0]] == OCCUPIED:
            return "in an occupied cell"
        return None

    def set_initial_pose(self, pose_xytheta, cov: np.ndarray | None = None) -> None:
        """Gaussian particle cloud around a map pose; refuses poses off the map or in a wall."""
        pose = np.asarray(pose_xytheta, dtype=float)
        why = self.start_refusal(pose)
        if why is not None:
            raise MapError(f"initial pose ({pose[0]:.2f}, {pose[1]:.2f}) is {why}",
                           field="initial_pose")
        cov = self.initial_cov() if cov is None else np.asarray(cov, dtype=float)
        self._reset_particles(self._gaussian_cloud(pose, cov, self.cfg.max_particles))
        self._est, self._cov = pose.copy(), cov.copy()

    def _gaussian_cloud(self, pose_xytheta: np.ndarray, cov: np.ndarray, n: int) -> np.ndarray:
        """``n`` particles (n, 3) drawn around a map pose with covariance ``cov`` (3, 3)."""
        pts = self.rng.multivariate_normal(pose_xytheta, cov, size=n, method="cholesky")
        pts[:, 2] = wrap_angle(pts[:, 2])
        return pts

    def estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """The current estimate without a new scan: (pose (3,) map frame [m, m, rad], its
        covariance (3, 3)); after :meth:`set_initial_pose`, that pose and covariance."""
        return self._est.copy(), self._cov.copy()

    def global_localization(self) -> None:
        """Particles uniform over the free cells, uniform heading."""
        free = self._free_cells()
        if len(free) == 0:
            raise MapError("the map has no free cell to spread particles over")
        n = self.cfg.max_particles
        pick = free[self.rng.integers(len(free), size=n)]
        jitter = self.rng.uniform(-0.5, 0.5, size=(n, 2)) * self.grid.resolution_m
        pts = np.column_stack([pick + jitter, self.rng.uniform(-np.pi, np.pi, n)])
        self._reset_particles(pts)
        self._est, self._cov = cluster_estimate(self.particles, self.weights)

    def _reset_particles(self, pts: np.ndarray) -> None:
        self.particles = pts
        self.weights = np.full(len(pts), 1.0 / len(pts))
        self.w_slow = self.w_fast = 0.0
        self._converged = False
        self._force_update = True
        self._coast_m = 0.0

    def _free_cells(self) -> np.ndarray:
        if self._free_xy is None:
            self._free_xy = self.grid.free_cells_world()
        return self._free_xy

    # ------------------------------------------------------------------- maps
    def set_map(self, grid: OccupancyGrid) -> None:
        """A new map: the particle set is kept (Nav2), the likelihood field replaced."""
        self.field.set_grid(grid.copy())
        self._free_xy = None

    def update_map_region(self, cells_new: np.ndarray, ix0: int, iy0: int) -> None:
        """Cells of the map changed (furniture moved): recompute that region of the field."""
        self.field.update_region(np.asarray(cells_new, dtype=np.int8), int(ix0), int(iy0))
        self._free_xy = None
        self.stats.map_region_updates += 1

    def apply_grid(self, grid: OccupancyGrid) -> None:
        """Bring the map to ``grid`` through one region update of the changed cells."""
        if self.field.apply_grid_diff(grid) is not None:
            self._free_xy = None
            self.stats.map_region_updates += 1

    # ----------------------------------------------------------------- update
    def update(self, odom_pose_xytheta, scan: Scan,
               withheld: np.ndarray | None = None) -> PoseEstimate:
        """Process one scan with the odometry pose (odom frame) at its stamp.

        ``withheld`` (B,) bool, optional: beams the caller set to NaN because the map cannot
        explain them (furniture moved, people); ``min_explained_beam_fraction`` counts them as
        unexplained beams."""
        c = self.cfg
        odom = np.asarray(odom_pose_xytheta, dtype=float)
        self.stats.scans += 1
        if len(self.particles) == 0:
            self.global_localization()
        if self._odom_at_update is None:
            self._odom_at_update = odom.copy()
            self._odom_last = odom.copy()
        step = _relative(self._odom_last, odom)
        reset_pts = None
        if np.hypot(step[0], step[1]) > c.odom_jump_m or abs(step[2]) > c.odom_jump_rad:
            self.stats.odom_resets += 1
            if not self._on_map(self._est):
                self.global_localization()
                self._odom_at_update = odom.copy()
            elif c.odom_jump_motion_weight >= 1.0:
                pass  # the step is motion, as AMCL (which has no jump test) takes every step
            elif c.odom_jump_motion_weight <= 0.0:
                # wheel slip or an odometry reset: restart around the last estimate
                self.set_initial_pose(self._est, self.initial_cov() * 4.0)
                self._odom_at_update = odom.copy()
            else:
                # either the odometry reset or slipped (the step is no motion: a cloud around
                # the last estimate) or the wheels caught up after a stall (the step is real
                # motion: the particles follow it, as AMCL's would); the scan decides. MIT
                # CSAIL stalls inside a turn and catches up 0.47 m / 85 deg in one step
                # (docs/experiments.md, sixty-ninth session).
                reset_pts = self._gaussian_cloud(self._est, self.initial_cov() * 4.0,
                                                 max(1, c.max_particles // 2))
                self.w_slow = self.w_fast = 0.0
                self._converged = False
                self._force_update = True
                self._coast_m = 0.0
        self._odom_last = odom.copy()
        delta = odom - self._odom_at_update
        delta[2] = wrap_angle(delta[2])
        need = (abs(delta[0]) > c.update_min_d_m or abs(delta[1]) > c.update_min_d_m
                or abs(delta[2]) > c.update_min_a_rad or self._force_update)
        updated = False
        n_beams = 0
        if need:
            t0 = time.perf_counter()
            moved = sample_motion(self.particles, self._odom_at_update, odom, c.odom_model,
                                  (c.alpha1, c.alpha2, c.alpha3, c.alpha4, c.alpha5), self.rng)
            if reset_pts is not None:  # the two hypotheses of a jump, each its prior mass
                a = c.odom_jump_motion_weight
                moved = np.concatenate([moved, reset_pts])
                self.weights = np.concatenate([self.weights * (a / self.weights.sum()),
                                               np.full(len(reset_pts),
                                                       (1.0 - a) / len(reset_pts))])
            # the gate holds from a converged filter on, while it coasts (its cloud spreads on
            # odometry alone), up to max_coast_m
            gate = (self._converged or self._coast_m > 0.0) and self._coast_m < c.max_coast_m
            predicted = (_compose(self._est, _relative(self._odom_at_update, odom))
                         if c.explained_at == "prediction" else None)
            logw, n_beams = self.sensor.weigh(moved, scan, self._converged,
                                              gate_unexplained=gate,
                                              predicted_xytheta=predicted,
                                              withheld=withheld)
            unmapped = getattr(self.sensor, "last_unmapped_beams", 0)
            self.stats.unmapped_beams += unmapped
            if getattr(self.sensor, "last_gated", False):
                self.stats.unexplained_skipped += 1
                self._coast_m += float(np.hypot(delta[0], delta[1]))
            elif n_beams > 0:
                self._coast_m = 0.0
            self.particles = moved
            self._odom_at_update = odom.copy()
            if n_beams == 0:
                self.stats.skipped_no_valid_beams += 1
            else:
                self._weigh_and_resample(logw, n_beams, recovery=unmapped <= (
                    c.recovery_max_unmapped_fraction * (unmapped + n_beams)))
                updated = True
                self._force_update = False
                self.stats.sensor_updates += 1
            self._est, self._cov = cluster_estimate(self.particles, self.weights)
            self._converged = self._is_converged()
            self.stats.update_ms.append((time.perf_counter() - t0) * 1e3)
        pose = _compose(self._est, _relative(self._odom_at_update, odom))
        return PoseEstimate(float(scan.stamp_s), pose, self._cov.copy(), len(self.particles),
                            self._converged, updated, n_beams)

    def _on_map(self, pose) -> bool:
        cell = self.grid.world_to_cell(np.asarray(pose)[None, :2])
        return bool(self.grid.in_bounds(cell)[0]) and \
            self.grid.cells[cell[0, 1], cell[0, 0]] != OCCUPIED

    def _weigh_and_resample(self, logw: np.ndarray, n_beams: int = 1,
                            recovery: bool = True) -> None:
        """Weigh by ``logw`` (N,), the log-likelihoods of ``n_beams`` beams, and resample;
        ``recovery``: this update may feed the recovery averages and inject random particles."""
        c = self.cfg
        if c.min_ess_fraction > 0:
            beta = tempering_factor(logw, self.weights, c.min_ess_fraction * len(logw))
            if beta < 1.0:
                logw = beta * logw
                self.stats.tempered_updates += 1
        # weights stay in AMCL's scale for the recovery averages: w = prior * p
        m = float(np.max(logw))
        w = self.weights * np.exp(logw - m)
        total = w.sum()
        if total <= 0 or not np.isfinite(total):
            w = np.full(len(w), 1.0 / len(w))
            log_total = -np.inf
        else:
            log_total = float(np.log(total)) + m
            w = w / total
        self.weights = w
        if recovery and (c.recovery_alpha_slow > 0 or c.recovery_alpha_fast > 0):
            # Prob. Rob. p. 258: the average measurement likelihood. AMCL divides the weighted
            # sum by N once more, which makes the averages jump whenever KLD changes N; the
            # weighted mean is N-independent.
            w_avg = float(np.exp(log_total)) if np.isfinite(log_total) else 0.0
            if c.recovery_per_beam and c.laser_model == "likelihood_field":
                w_avg = max(w_avg - 1.0, 0.0) / max(n_beams, 1)  # p = 1 + sum of pz^3
            elif c.recovery_per_beam:  # p = product over the beams: the geometric mean
                w_avg = float(np.exp(log_total / max(n_beams, 1))) if w_avg > 0.0 else 0.0
            if self.w_slow == 0.0:
                self.w_slow = w_avg
            else:
                self.w_slow += c.recovery_alpha_slow * (w_avg - self.w_slow)
            if self.w_fast == 0.0:
                self.w_fast = w_avg
            else:
                self.w_fast += c.recovery_alpha_fast * (w_avg - self.w_fast)
        self._updates_since_resample += 1
        if self._updates_since_resample < c.resample_interval:
            return
        if c.selective_resampling and 1.0 / np.sum(w**2) > len(w) / 2.0:
            return
        self._updates_since_resample = 0
        new = kld_resample(self.particles, w, self.rng, err=c.kld_err, z=c.kld_z,
                           min_n=c.min_particles, max_n=c.max_particles)
        p_inject = 0.0
        if recovery and self.w_slow > 0:
            p_inject = max(0.0, 1.0 - self.w_fast / self.w_slow)
        if p_inject > 0:
            inject = self.rng.random(len(new)) < p_inject
            k = int(inject.sum())
            if k:
                free = self._free_cells()
                pick = free[self.rng.integers(len(free), size=k)]
                new[inject] = np.column_stack([pick, self.rng.uniform(-np.pi, np.pi, k)])
                self.stats.random_injected += k
                # AMCL resets w_slow and w_fast here, which stops injection after one round
                # while the robot is still lost; Augmented MCL (Prob. Rob. Table 8.3) keeps
                # injecting as long as the short-term average is below the long-term one.
        self.particles = new
        self.weights = np.full(len(new), 1.0 / len(new))

    def _is_converged(self) -> bool:
        return is_converged(self.particles, self.cfg.converged_dist_m)


def effective_sample_size(weights: np.ndarray) -> float:
    """1 / sum(w^2) of the normalized weights (N,)."""
    w = np.asarray(weights, dtype=float)
    total = w.sum()
    if total <= 0 or not np.isfinite(total):
        return 0.0
    w = w / total
    return float(1.0 / np.sum(w**2))


def tempering_factor(logw: np.ndarray, prior: np.ndarray, min_ess: float,
                     iters: int = 30) -> float:
    """The largest beta in (0, 1] for which the weights ``prior * exp(beta * logw)`` (N,) keep
    an effective sample size of at least ``min_ess`` (1 if beta = 1 does; bisection). Adaptive
    likelihood tempering: a sharp sensor model over a wide cloud otherwise leaves a handful of
    particles, whichever happened to fit best, and the filter cannot recover the truth if none
    of them was near it."""
    lw = np.asarray(logw, dtype=float)
    lw = lw - np.max(lw)
    prior = np.asarray(prior, dtype=float)
    if len(prior) != len(lw) or not np.all(np.isfinite(lw)):
        return 1.0

    def ess(beta: float) -> float:
        return effective_sample_size(prior * np.exp(beta * lw))

    if ess(1.0) >= min_ess:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        if ess(mid) >= min_ess:
            lo = mid
        else:
            hi = mid
    return max(lo, 1e-6)
